"""`make bench`: run every bench/bench_*.py side by side and write bench/results.json.

Each module exposes `run() -> list[dict]`, each dict `{name, ratio, contender, baseline}`
(plus any extra fields: medians in seconds, repeats). Ratios are measured within one run,
baseline time / contender time, from medians of several repeats: the machines are noisy.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> int:
    results = []
    only = set(sys.argv[1:])
    for path in sorted(HERE.glob("bench_*.py")):
        if only and path.stem not in only:
            continue
        spec = importlib.util.spec_from_file_location(path.stem, path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        for r in mod.run():
            print(
                f"{r['name']}: {r['ratio']:.2f}x  ({r['contender']} vs {r['baseline']})", flush=True
            )
            results.append(r)
    out = HERE / "results.json"
    if only and out.exists():
        # A partial run (`bench/run.py bench_noise …`) replaces its own entries only.
        new = {r["name"] for r in results}
        results = [r for r in json.loads(out.read_text()) if r["name"] not in new] + results
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
