"""NumPy arrays to Arrow arrays and back, through their buffers.

pyarrow imports pandas, where it is installed, the first time it converts a Python or NumPy
value (``pa.array``, ``pa.scalar``, ``Array.to_numpy``, a Python scalar handed to a compute
function): it looks for pandas' own types. Importing pandas is about 0.2 s, a fifth of a warm
``pamid fit`` of a one-muscle file, which otherwise has no use for it (benchmarks/README.md,
"A fit without pandas"). The reader and the JSON writer convert here instead: the same
values, by the buffers' layout (the Arrow columnar format: a validity bitmap, little-endian
bits, then the values; for strings int32 offsets then UTF-8 bytes), which pyarrow does not
check. Only what pamid converts is covered: 1-D numeric and boolean arrays, strings.
"""

from __future__ import annotations

import numpy as np

__all__ = ["constant_strings", "from_numpy", "null_strings", "strings", "to_numpy"]

#: The NumPy dtype of each Arrow type this module converts, by the type's name.
_NUMPY = {"int8": np.int8, "int16": np.int16, "int32": np.int32, "int64": np.int64,
          "uint8": np.uint8, "uint16": np.uint16, "uint32": np.uint32, "uint64": np.uint64,
          "halffloat": np.float16, "float": np.float32, "double": np.float64}


def to_numpy(array) -> np.ndarray:
    """The values of an Arrow numeric or boolean array (or chunked array) as a NumPy
    array: a view of the values where they are one buffer without nulls, as
    ``Array.to_numpy`` gives; nulls as NaN (integers become float64 then, as pyarrow does).
    """
    import pyarrow as pa

    if isinstance(array, pa.ChunkedArray):
        array = (array.combine_chunks() if array.num_chunks != 1 else array.chunk(0))
    n, offset = len(array), array.offset
    validity, data = array.buffers()[:2]
    if pa.types.is_boolean(array.type):
        values = _bits(data, offset, n)
    else:
        dtype = _NUMPY.get(str(array.type))
        if dtype is None:
            raise TypeError(f"no NumPy view of an Arrow {array.type} array")
        values = (np.frombuffer(data, dtype=dtype, count=offset + n)[offset:]
                  if n else np.zeros(0, dtype=dtype))
    if array.null_count:
        valid = _bits(validity, offset, n)
        values = np.where(valid, values, np.nan)
    return values


def _bits(buffer, offset: int, n: int) -> np.ndarray:
    """Bits ``offset`` … ``offset + n − 1`` of an Arrow bitmap as a bool array."""
    if n == 0:
        return np.zeros(0, dtype=bool)
    raw = np.frombuffer(buffer, dtype=np.uint8)
    return np.unpackbits(raw, count=offset + n, bitorder="little")[offset:].astype(bool)


def from_numpy(values: np.ndarray):
    """A 1-D NumPy numeric or boolean array as an Arrow array of the same values (no
    nulls; NaN stays NaN)."""
    import pyarrow as pa

    values = np.ascontiguousarray(values)
    if values.ndim != 1:
        raise ValueError("from_numpy takes a 1-D array")
    n = len(values)
    if values.dtype == bool:
        data = np.packbits(values, bitorder="little")
        return pa.Array.from_buffers(pa.bool_(), n, [None, pa.py_buffer(data)])
    kind = {np.dtype(v): k for k, v in _NUMPY.items()}.get(values.dtype)
    if kind is None:
        raise TypeError(f"no Arrow array of a NumPy {values.dtype} array")
    return pa.Array.from_buffers(pa.from_numpy_dtype(values.dtype), n,
                                 [None, pa.py_buffer(values)])


def strings(texts: list[str]):
    """A list of str as an Arrow string array (no nulls)."""
    import pyarrow as pa

    encoded = [text.encode() for text in texts]
    offsets = np.zeros(len(encoded) + 1, dtype=np.int64)
    np.cumsum([len(b) for b in encoded], out=offsets[1:])
    data = b"".join(encoded)
    if offsets[-1] < 2**31:
        kind, offsets = pa.string(), offsets.astype(np.int32)
    else:
        kind = pa.large_string()
    return pa.Array.from_buffers(kind, len(encoded), [None, pa.py_buffer(offsets),
                                                      pa.py_buffer(data)])


def constant_strings(text: str, n: int):
    """An Arrow string array of ``n`` copies of ``text``: where a compute function would
    take the Python str (``pa.scalar`` would import pandas)."""
    import pyarrow as pa

    data = text.encode()
    offsets = (np.arange(n + 1, dtype=np.int64) * len(data))
    kind = pa.string() if offsets[-1] < 2**31 else pa.large_string()
    if kind == pa.string():
        offsets = offsets.astype(np.int32)
    return pa.Array.from_buffers(kind, n, [None, pa.py_buffer(offsets),
                                           pa.py_buffer(data * n)])


def null_strings(n: int):
    """An Arrow string array of ``n`` nulls."""
    import pyarrow as pa

    validity = np.zeros((n + 7) // 8, dtype=np.uint8)
    offsets = np.zeros(n + 1, dtype=np.int32)
    return pa.Array.from_buffers(pa.string(), n, [pa.py_buffer(validity),
                                                  pa.py_buffer(offsets), pa.py_buffer(b"")],
                                 null_count=n)
