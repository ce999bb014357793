"""Benchmarks: `make bench` (python -m benchmarks [NAME ...]) writes bench-results/NAME.json.

Each `benchmarks/bench_NAME.py` defines `run(out_dir: pathlib.Path) -> dict`; the runner
adds the commit and the time and writes the JSON. Ratios are measured side by side in one run.
"""
