"""dlo-course: deep reinforcement learning for the shape control of deformable linear objects.

Importing the package registers the environment ``DLOShape-v0`` with Gymnasium.
"""

from gymnasium.envs.registration import register, registry

from dlo_course.database import Database, load_database

__version__ = "0.1.0"

if "DLOShape-v0" not in registry:
    # 300 steps: the paper's training episode. Tests use 30 (pass max_episode_steps).
    register(id="DLOShape-v0", entry_point="dlo_course.env:DLOShapeEnv", max_episode_steps=300)

__all__ = ["Database", "load_database", "__version__"]
