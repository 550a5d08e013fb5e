"""The export targets, `blurset export --for NAME`: one module per target in this
package, named as the target, whose `TARGET` (an export_rules.Target) declares all that
sets it apart; blurset.commands.export.cli writes any of them and names none. A new target is a new
module here, its docs page, and its name in `ExportTarget` (rust/core/src/dataset/records.rs),
which export.json's `for` is read as.
"""

from __future__ import annotations

import importlib
import pkgutil
from functools import cache

from blurset.commands.export.rules import Target
from blurset.exceptions import ConfigError

# `--for` without it: the LLFF folder every GNeRF loader but GeoNeRF's reads.
DEFAULT = "llff"


@cache
def targets() -> dict[str, Target]:
    """Every target by name, found by its module in this package."""
    out: dict[str, Target] = {}
    for m in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        target = getattr(importlib.import_module(f"{__name__}.{m.name}"), "TARGET", None)
        if not isinstance(target, Target) or target.name != m.name:
            # A programming error, not bad input: the registry is the package itself.
            raise TypeError(f"{__name__}.{m.name} declares no TARGET named {m.name!r}")
        out[target.name] = target
    return out


def get(name: str) -> Target:
    """The target `--for NAME` names."""
    try:
        return targets()[name]
    except KeyError:
        raise ConfigError(f"--for {name}: no such export target ({', '.join(targets())})") from None
