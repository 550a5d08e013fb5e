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
# `make bench-gpu` (issue 47): what one GPU node pays, in one command: the unit costs of a
# render call and a sample (and its CPU's beside them), where a call's fixed cost goes, speed at equal accuracy of the
# accuracy presets against the paper preset on two held-out models, and one whole setting.
GPU_BENCHES = (
    "bench_device_costs",
    "bench_call_cost",
    "bench_target_speed",
    "bench_one_setting",
)
# Their sizes under --device, unless set: 512 px, one view a model, the runs the issue's
# figures need ((a) at the paper's worst image, (b) its accuracy against the continuous blur).
DEVICE_SIZES = {
    "BLURSET_BENCH_CALL_RES": "512",
    "BLURSET_BENCH_SPEED_RES": "512",
    "BLURSET_BENCH_SPEED_VIEWS": "1",
    "BLURSET_BENCH_SPEED_RUNS": "worst,continuous",
}


def pick_device(name: str) -> str:
    """The Cycles backend for `--device NAME`, or SystemExit naming what exists."""
    from blurset.exceptions import ConfigError
    from blurset.services import devices

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
        for k, v in DEVICE_SIZES.items():
            os.environ.setdefault(k, v)
        if "BLURSET_BENCH_GLBS" not in os.environ:
            # Two held-out models (bench_target's first two): the "both models".
            sys.path.insert(0, str(HERE))
            from bench_target import held_out_glbs

            os.environ["BLURSET_BENCH_GLBS"] = ",".join(str(p) for p in held_out_glbs(None)[:2])
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
