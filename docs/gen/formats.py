"""Write one page per record under docs/formats/records/ from schemas/*.schema.json.

Run by `make docs`. The schemas are generated from the core's serde types
(`make schemas`), so a page lists exactly the fields, types and descriptions of the
files blurset writes. Each page also ships its schema file for validators.
"""

from __future__ import annotations

import json
import re
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import sanitize  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCHEMAS = ROOT / "schemas"
OUT = ROOT / "docs" / "formats" / "records"

# Where each record lives and who writes it (the schemas say what is inside).
WHERE = {
    "dataset": (
        "dataset.json",
        "`OUT/dataset.json`",
        "`blurset build`: the options, versions, seed and counts of a build. The first run "
        "writes a provisional one (`provisional: true`) before any setting; every finished "
        "run rewrites it.",
    ),
    "meta": (
        "meta.json",
        "`OUT/<setting>/meta.json`",
        "`blurset build`, one per setting: every number sampled for it (views, trajectories, "
        "blur weights, latent positions, seeds), how it was rendered, and where the object "
        "came from.",
    ),
    "splits": (
        "splits.json",
        "`OUT/splits.json` (copied into a whole-build noise output)",
        "`blurset build`: the train and test settings and the held-out views of each.",
    ),
    "noise": (
        "noise.json",
        "`gain_<g>/noise.json` in every noisy scene",
        "`blurset noise`: the gain, σ of read and shot noise, white balance, seed and the "
        "files of one noisy scene.",
    ),
    "noise_dataset": (
        "noise_dataset.json",
        "`NOISE/noise_dataset.json`",
        "`blurset noise BUILD`: the options, per-(setting, level) seeds, gains and counts of "
        "a whole-build noise output.",
    ),
    "noise_scene": (
        "noise_scene.json",
        "`NOISE/noise_scene.json`",
        "`blurset noise SCENE`: what a single-scene noise output is, written last.",
    ),
    "export": (
        "export.json",
        "`EXPORT/export.json`",
        "`blurset export`: what was exported, for which loader, the `llffhold` to use and "
        "the entries the export owns.",
    ),
    "stats": (
        "stats.json",
        "`OUT/stats/stats.json` (or `stats --out DIR`)",
        "`blurset stats`: the statistics of a build as named numbers.",
    ),
}

FORMATS = {
    "uint": "≥ 0",
    "uint8": "≥ 0",
    "uint16": "≥ 0",
    "uint32": "≥ 0",
    "uint64": "≥ 0",
    "int": "",
    "int32": "",
    "int64": "",
    "double": "",
    "float": "",
}


def _text(s: str | None) -> str:
    return sanitize(" ".join((s or "").split())).replace("|", "\\|")


def _anchor(name: str) -> str:
    return "def-" + re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def type_of(s: object) -> str:
    """A short, linked type of a schema node."""
    if s is True or s == {}:
        return "any"
    if not isinstance(s, dict):
        return "any"
    if "$ref" in s:
        name = s["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#{_anchor(name)})"
    if "const" in s:
        return f"`{json.dumps(s['const'])}`"
    if "enum" in s:
        return "one of " + ", ".join(f"`{json.dumps(v)}`" for v in s["enum"])
    for key in ("oneOf", "anyOf", "allOf"):
        if key in s:
            parts = [type_of(x) for x in s[key]]
            return " or ".join(dict.fromkeys(parts))
    t = s.get("type")
    types = t if isinstance(t, list) else [t] if t else []
    out = []
    for one in types:
        if one == "array":
            items = s.get("items", True)
            n = ""
            if s.get("minItems") is not None and s.get("minItems") == s.get("maxItems"):
                n = f"{s['minItems']} × "
            if isinstance(items, list):  # a tuple
                out.append("[" + ", ".join(type_of(i) for i in items) + "]")
            else:
                out.append(f"array of {n}{type_of(items)}")
        elif one == "object":
            extra = s.get("additionalProperties")
            if isinstance(extra, dict) and "properties" not in s:
                out.append(f"map of string → {type_of(extra)}")
            else:
                out.append("object")
        elif one == "integer":
            bound = FORMATS.get(s.get("format", ""), "")
            out.append(f"integer {bound}".strip())
        elif one == "number":
            out.append("number")
        elif one is not None:
            out.append(str(one))
    if not out:
        return "any"
    return " or ".join(out)


def _enum_variants(s: dict) -> list[tuple[str, str]] | None:
    """(value, description) of a string enum written as oneOf consts (serde's style)."""
    if "enum" in s:
        return [(json.dumps(v), "") for v in s["enum"]]
    variants = s.get("oneOf") or s.get("anyOf")
    if not variants:
        return None
    out = []
    for v in variants:
        if not isinstance(v, dict):
            return None
        if "const" in v:
            out.append((json.dumps(v["const"]), _text(v.get("description"))))
        elif "enum" in v:
            out += [(json.dumps(x), _text(v.get("description"))) for x in v["enum"]]
        else:
            return None
    return out


def _table(s: dict) -> list[str]:
    props = s.get("properties") or {}
    required = set(s.get("required") or [])
    lines = ["| field | type | required | description |", "| --- | --- | --- | --- |"]
    for name in sorted(props, key=lambda n: (n not in required, n)):
        p = props[name]
        desc = _text(p.get("description") if isinstance(p, dict) else "")
        if isinstance(p, dict) and "default" in p:
            desc += f" Default: `{json.dumps(p['default'])}`."
        lines.append(
            f"| `{name}` | {type_of(p)} | {'yes' if name in required else 'no'} | {desc.strip()} |"
        )
    if s.get("additionalProperties") is False:
        lines.append("")
        lines.append("No other fields.")
    return lines


def _node(title: str | None, s: dict, level: str = "##") -> list[str]:
    out: list[str] = []
    if title:
        out += [f"{level} {title} {{ #{_anchor(title)} }}", ""]
    if s.get("description"):
        out += [_text(s["description"]), ""]
    variants = _enum_variants(s)
    if variants is not None and "properties" not in s:
        out += ["| value | meaning |", "| --- | --- |"]
        out += [f"| `{v}` | {d} |" for v, d in variants]
        out.append("")
    elif "properties" in s:
        out += _table(s) + [""]
    else:
        out += [f"Type: {type_of(s)}.", ""]
    return out


def _reachable(schema: dict) -> list[str]:
    """Definitions in the order a reader meets them from the top."""
    defs = schema.get("$defs") or {}
    seen: list[str] = []

    def walk(node: object) -> None:
        if isinstance(node, dict):
            ref = node.get("$ref")
            if isinstance(ref, str) and ref.startswith("#/$defs/"):
                name = ref.rsplit("/", 1)[-1]
                if name not in seen and name in defs:
                    seen.append(name)
                    walk(defs[name])
            for k, v in node.items():
                if k != "$defs":
                    walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(schema)
    return seen + [n for n in sorted(defs) if n not in seen]


def page(stem: str, schema: dict) -> str:
    file_name, where, what = WHERE.get(
        stem, (f"{stem}.json", "(not described yet)", schema.get("description", ""))
    )
    out = [
        f"# {file_name}",
        "",
        f"Written by {what}",
        "",
        f"Where: {where}. JSON Schema (draft 2020-12): "
        f"[{stem}.schema.json]({stem}.schema.json), generated from the core's types; "
        "blurset reads the file through the same types, so a file of another shape is "
        "refused with one line naming the file and the field.",
        "",
        "The field names are a contract that other tools read: later versions add "
        "fields, they do not rename these.",
        "",
    ]
    if "anyOf" in schema and "properties" not in schema:
        out += ["The file is one of:", ""]
        for v in schema["anyOf"]:
            out.append(f"- {type_of(v)}: {_text(_def(schema, v).get('description'))}")
        out.append("")
    else:
        out += ["## Top level", ""] + _node(None, schema)[0:]
    for name in _reachable(schema):
        out += _node(name, schema["$defs"][name])
    return "\n".join(out).rstrip() + "\n"


def _def(schema: dict, node: dict) -> dict:
    ref = node.get("$ref", "")
    return schema.get("$defs", {}).get(ref.rsplit("/", 1)[-1], node)


def main() -> int:
    if OUT.exists():
        shutil.rmtree(OUT)
    OUT.mkdir(parents=True)
    stems = []
    for path in sorted(SCHEMAS.glob("*.schema.json")):
        stem = path.name.removesuffix(".schema.json")
        schema = json.loads(path.read_text())
        (OUT / f"{stem}.md").write_text(page(stem, schema))
        shutil.copy(path, OUT / path.name)
        stems.append(stem)
    nav = (ROOT / "mkdocs.yml").read_text()
    missing = [s for s in stems if f"formats/records/{s}.md" not in nav]
    if missing:
        print(
            "docs/gen/formats.py: add to mkdocs.yml's nav: "
            + ", ".join(f"formats/records/{s}.md" for s in missing),
            file=sys.stderr,
        )
        return 1
    print(f"wrote {len(stems)} record pages in {OUT}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
