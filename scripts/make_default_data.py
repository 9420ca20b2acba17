"""Write the bundled default data set of `pamid demo` (see pamid/_data/_default.py)."""

from pamid._data._default import default_bench_path, simulate_default_bench
from pamid._io import write_frame_atomic

if __name__ == "__main__":
    path = write_frame_atomic(default_bench_path(), simulate_default_bench())
    print(f"wrote {path}")
