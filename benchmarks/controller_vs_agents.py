"""Benchmark (not a test): the classical controller's Table I cells beside the agents', from kept runs.

Reads (or, for what is missing, runs) the evaluation runs that `dlo-course reproduce` keeps in
`docs/reproduction/runs/`, for the 12 cells with reinitialisation on the paper's test goals:
the Jacobian shape-servoing controller (`dlo_course/jacobian.py`) and the shipped agents, the
same 100 episodes per cell. Writes `benchmarks/results/jacobian/table1_jacobian_with_reinit.md`
and `.csv` (the controller against the paper, reproduce's format) and `versus_agents.md`
(controller, agent and paper side by side).

    python benchmarks/controller_vs_agents.py      # seconds when every run is kept

Filling the cache from scratch is what `mpiexec -n 2 dlo-course reproduce --controller
jacobian --out docs/reproduction` does (about 1.5 hours on 2 cores for the controller's 6 runs
and the agents').
"""

from __future__ import annotations

from pathlib import Path

from dlo_course.paths import AGENTS_DIR, REPO_ROOT
from dlo_course.reproduce import (evaluate_cells, evaluate_controller_cells, read_paper_table,
                                  table1_cells, verdict, write_table)

CACHE = REPO_ROOT / "docs" / "reproduction" / "runs"
RESULTS = Path(__file__).parent / "results" / "jacobian"


def main() -> None:
    cells = [c for c in table1_cells() if c.reinit == "with"]
    paper = read_paper_table()
    agents = evaluate_cells(AGENTS_DIR, 100, 30, 0, cells=cells, protocol="test", cache=CACHE)
    controller = evaluate_controller_cells("jacobian", 100, 30, 0, cells=cells,
                                           protocol="test", cache=CACHE)
    write_table(controller, paper, RESULTS, name="table1_jacobian_with_reinit")
    lines = ["| nodes | db | thr (m) | Jacobian controller: done % (95% CI) | verdict vs paper | "
             "shipped agent: done % (95% CI) | paper |", "|---|---|---|---|---|---|---|"]
    for ours, agent in zip(controller, agents):
        cell = ours["cell"]
        ref = paper[cell.key]["done_percent"]
        lines.append(
            f"| {cell.nodes} | {cell.database} | {cell.threshold} | {ours['done_percent']:.0f} "
            f"({ours['done_ci_low']:.0f}-{ours['done_ci_high']:.0f}) | {verdict(ours, ref)} | "
            f"{agent['done_percent']:.0f} ({agent['done_ci_low']:.0f}-"
            f"{agent['done_ci_high']:.0f}) | {ref:.1f} |")
    (RESULTS / "versus_agents.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
