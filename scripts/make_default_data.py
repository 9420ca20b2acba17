"""Write the bundled default data set of `pamid demo` (see pamid/_virtual/_default.py)."""

from pamid._io import write_frame_atomic
from pamid._virtual._default import default_bench_path, simulate_default_bench

if __name__ == "__main__":
    path = write_frame_atomic(default_bench_path(), simulate_default_bench())
    print(f"wrote {path}")
