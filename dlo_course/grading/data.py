"""The plain data that travels between the sandbox and the grader: JSON that cannot carry
code (numbers, strings, containers, bytes, NumPy arrays and scalars, torch tensors).
"""

from __future__ import annotations

from typing import Any


class DataError(TypeError):
    """A value that cannot travel between the sandbox and the grader as plain data."""


def encode_data(obj: Any, _depth: int = 0) -> Any:
    """``obj`` as JSON-compatible data: None, bool, int, float, str, bytes, list, tuple, dict,
    set, NumPy arrays and scalars, torch tensors (detached). Anything else raises DataError."""
    if _depth > 64:
        raise DataError("the value is nested too deeply")
    kind = type(obj)
    if obj is None or kind in (bool, int, float, str):
        return obj
    if kind in (list, tuple, set, frozenset, dict) or isinstance(obj, (list, tuple, dict)):
        if isinstance(obj, dict):
            return {"__dict__": [[encode_data(k, _depth + 1), encode_data(v, _depth + 1)]
                                 for k, v in obj.items()]}
        items = [encode_data(x, _depth + 1) for x in obj]
        if isinstance(obj, list):
            return items
        return {"__tuple__" if isinstance(obj, tuple) else "__set__": items}
    if isinstance(obj, (bytes, bytearray)):
        import base64

        return {"__bytes__": base64.b64encode(bytes(obj)).decode("ascii")}
    if isinstance(obj, (bool, int, float, str)):  # subclasses (IntEnum, numpy.float64, ...)
        import numpy as np

        if isinstance(obj, np.generic):
            return {"__scalar__": encode_data(np.asarray(obj), _depth + 1)}
        return (bool if isinstance(obj, bool) else int if isinstance(obj, int)
                else float if isinstance(obj, float) else str)(obj)
    module = getattr(kind, "__module__", "") or ""
    if module.startswith("torch") and hasattr(obj, "detach"):
        t = obj.detach().cpu()
        if str(t.dtype) == "torch.bfloat16":
            t = t.float()
        return {"__tensor__": encode_data(t.numpy(), _depth + 1),
                "requires_grad": bool(obj.requires_grad)}
    import numpy as np

    if isinstance(obj, np.generic):
        return {"__scalar__": encode_data(np.asarray(obj), _depth + 1)}
    if isinstance(obj, np.ndarray):
        import base64

        if obj.dtype.kind not in "biufc":
            return {"__objarray__": encode_data(obj.tolist(), _depth + 1)}
        return {"__ndarray__": [obj.dtype.str, list(obj.shape),
                                base64.b64encode(obj.tobytes(order="C")).decode("ascii")]}
    raise DataError(f"a {kind.__module__}.{kind.__qualname__} cannot be sent to the grader "
                    f"(only numbers, strings, containers, arrays and tensors)")


def decode_data(data: Any) -> Any:
    """The inverse of :func:`encode_data` (arrays are NumPy arrays, tensors torch tensors)."""
    if isinstance(data, list):
        return [decode_data(x) for x in data]
    if not isinstance(data, dict):
        return data
    if "__dict__" in data:
        return {_hashable(decode_data(k)): decode_data(v) for k, v in data["__dict__"]}
    if "__tuple__" in data:
        return tuple(decode_data(x) for x in data["__tuple__"])
    if "__set__" in data:
        return {_hashable(decode_data(x)) for x in data["__set__"]}
    if "__bytes__" in data:
        import base64

        return base64.b64decode(data["__bytes__"])
    import numpy as np

    if "__ndarray__" in data:
        import base64

        dtype, shape, payload = data["__ndarray__"]
        dtype = np.dtype(str(dtype))
        if dtype.kind not in "biufc":
            raise DataError(f"unexpected dtype {dtype}")
        return np.frombuffer(base64.b64decode(payload), dtype=dtype).reshape(
            [int(n) for n in shape]).copy()
    if "__objarray__" in data:
        return np.array(decode_data(data["__objarray__"]), dtype=object)
    if "__scalar__" in data:
        return decode_data(data["__scalar__"])[()]
    if "__tensor__" in data:
        import torch

        return torch.from_numpy(decode_data(data["__tensor__"]))
    raise DataError(f"unknown data {sorted(data)[:3]}")


def _hashable(value: Any) -> Any:
    if isinstance(value, list):
        return tuple(_hashable(v) for v in value)
    return value
