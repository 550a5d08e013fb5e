"""`make bench`: run every bench/bench_*.py side by side and write bench/results.json.

Each module exposes `run() -> list[dict]`, each dict `{name, ratio, contender, baseline}`
(plus any extra fields: medians in seconds, repeats). Ratios are measured within one run,
baseline time / contender time, from medians of several repeats: the machines are noisy.

`bench/run.py --device gpu|cpu|auto|optix|cuda|hip|oneapi|metal [bench_… …]` renders on that
Cycles device (`gpu`: the best GPU backend; refused, with what exists, on a machine without
one) and writes bench/results_<device>.json; without modules it runs the rendering
benchmarks GPU_BENCHES (`make bench-gpu`).
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
GPU_BENCHES = (
    "bench_device_costs",
    "bench_blur_cost",
    "bench_denoise_gain",
    "bench_settings_per_hour",
)


def pick_device(name: str) -> str:
    """The Cycles backend for `--device NAME`, or SystemExit naming what exists."""
    from blurset import devices
    from blurset.exceptions import ConfigError

    if name == "cpu":
        return "CPU"
    available = devices.probe(None)
    gpu = [b for b in devices.GPU_BACKENDS if available.get(b)]
    try:
        if name == "gpu":
            if not gpu:
                raise ConfigError(
                    f"--device gpu: no GPU backend in this Blender's Cycles "
                    f"({devices.describe(available)}); run with --device cpu"
                )
            return gpu[0]
        return devices.resolve(name, None, available)[0]
    except ConfigError as e:
        raise SystemExit(f"bench/run.py: {e}") from None


def machine() -> str:
    """The CPU this run measured on (model name and cores): results from different
    machines share results.json, and a ratio holds on one machine only."""
    model = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores"


def main() -> int:
    results = []
    argv = sys.argv[1:]
    out = HERE / "results.json"
    if "--device" in argv:
        i = argv.index("--device")
        if i + 1 >= len(argv):
            raise SystemExit("bench/run.py: --device needs a value (gpu, cpu, auto, optix …)")
        name = argv[i + 1].lower()
        del argv[i : i + 2]
        backend = pick_device(name)
        os.environ["BLURSET_BENCH_DEVICE"] = backend
        print(f"rendering on {backend}", flush=True)
        out = HERE / f"results_{name}.json"
        argv = argv or list(GPU_BENCHES)
    only = set(argv)
    for path in sorted(HERE.glob("bench_*.py")):
        if only and path.stem not in only:
            continue
        spec = importlib.util.spec_from_file_location(path.stem, path)
        assert spec is not None and spec.loader is not None  # a .py file: a spec and a loader
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        for r in mod.run():
            r.setdefault("machine", machine())
            print(
                f"{r['name']}: {r['ratio']:.2f}x  ({r['contender']} vs {r['baseline']})", flush=True
            )
            results.append(r)
    if only and out.exists():
        # A partial run (`bench/run.py bench_noise …`) replaces its own entries only.
        new = {r["name"] for r in results}
        results = [r for r in json.loads(out.read_text()) if r["name"] not in new] + results
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
