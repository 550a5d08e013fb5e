"""What blurset writes and what a command may touch: the Python face of the core's one
owner (blurset-core `dataset::outputs`, DESIGN §10).

- Every output names its kind in a record (`OutputKind.record`): a build's
  dataset.json, a noise output's noise_dataset.json or noise_scene.json, an export's
  export.json, a statistics folder's stats.json. `kind_of` reads it.
- `claim` says whether a command may write into a folder; `owned_entries` /
  `remove_owned` are the only entries its re-run or `--overwrite` replaces.
- `lock` is the lock a writer of a kind holds in its folder for the whole run.
- `build_state` says whether a build is finished; `finished_build` refuses a provisional
  one for the readers that describe or pass on a build (export, card, noise).
- `write_marked_text` writes a text file (a dataset card) that a later run tells from an
  edited or foreign one: those are replaced only with `force`, the old kept as `.bak`.
- `read_record` reads a record checked against its shape.
- `claim_report` says whether a command may write its JSON report to a file the user
  named: nothing there, or an earlier report of its own; never a build's record or
  another file of the user's.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import re
import socket
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import IO, Any

from blurset import _core, layout
from blurset.exceptions import ConfigError, InputError

OutputKind = _core.OutputKind
BuildState = _core.BuildState


def path_problem(value: str | Path, *, output: bool = False) -> str | None:
    """What is wrong with a path a user gave (a flag or a TOML key), as the words after
    its name, or None: an empty path (Path("") is the current folder: it would write
    there), or, for an output (`output`), a link to nothing (resolved, it would name and
    create the link's target anywhere on disk). The one check of both the flags and the
    config file."""
    text = str(value)
    if not text.strip():
        return "is empty (it would mean the current folder): give a file or folder"
    if output and Path(text).is_symlink() and not Path(text).exists():
        return f"is a link to nothing: {text}"
    return None


def kind_of(path: Path) -> _core.OutputKind | None:
    """The kind of blurset output `path` is, from its record (None: not an output)."""
    return _core.output_kind(Path(path))


def claim(
    path: Path, kind: _core.OutputKind, option: str = "--out", within: Path | None = None
) -> str:
    """`new`, `empty`, `same` (an output of this kind: the caller compares records) or
    `beside` (an export among other things); ConfigError naming `option` and the folder
    when the command may not write there (a file, another kind's output, a foreign
    folder, a folder inside another output: only `within`, the output a command
    describes, e.g. a build's own stats/, may hold it). A link by the name of the kind's
    lock is refused (InputError) here, before anything is written."""
    refuse_inside_output(path, option, within=within)
    lock_path = Path(path) / kind.lock_name
    if lock_path.is_symlink():
        raise _not_a_lock(lock_path, "a link")
    return _core.claim(Path(path), kind, option)


def is_tradeoff(path: Path) -> bool:
    """A folder `blurset tradeoff` wrote: its tradeoff.json says so (`kind`)."""
    try:
        doc = json.loads((Path(path) / TRADEOFF_RECORD).read_bytes())
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and doc.get("kind") == TRADEOFF_KIND


# `blurset tradeoff` measures and writes no dataset: its folder is recognised here, by
# its record, and no other command writes into it.
TRADEOFF_RECORD = "tradeoff.json"
TRADEOFF_KIND = "blurset tradeoff"
TRADEOFF_LOCK = ".tradeoff.lock"


def enclosing_output(path: Path, include_self: bool = False) -> tuple[Path, str] | None:
    """The nearest folder above `path` (links resolved; `path` itself too with
    `include_self`) that is a blurset output, with how messages name its kind (`build`,
    `noise output`, … `tradeoff folder`), or None."""
    p = Path(path).expanduser().resolve()
    for d in [p, *p.parents] if include_self else p.parents:
        try:
            k = kind_of(d)
        except InputError:
            return d, "output"  # two outputs' records: an output all the same
        except OSError:
            continue  # a folder we may not list holds no output we wrote
        # (A `.lock` alone, which a build's first moments hold, is not enough above a
        # path: other tools name their locks so too, pytest's temp folders among them.)
        if k is not None and (k is not OutputKind.BUILD or (d / k.record).is_file()):
            return d, k.label
        if is_tradeoff(d):
            return d, "tradeoff folder"
    return None


def refuse_inside_output(
    path: Path, option: str = "--out", within: Path | None = None, include_self: bool = False
) -> None:
    """ConfigError naming `option` when `path` lies inside a blurset output other than
    `within` (the output a command may write into: a build's own statistics or card),
    or with `include_self` is one: a command writes only in its own output, and one
    output never holds another's files (the other's MANIFEST would list them and
    `verify` certify them)."""
    found = enclosing_output(path, include_self)
    if found is None:
        return
    folder, what = found
    if within is not None and folder == Path(within).expanduser().resolve():
        return
    raise ConfigError(
        f"{option} lies inside the blurset {what} {str(folder)!r}, which this command does "
        f"not write: give a path outside it (nothing was written): {path}"
    )


def owned_entries(path: Path, kind: _core.OutputKind) -> list[str]:
    """The entries (relative paths) the output of `kind` in `path` wrote."""
    return _core.owned_entries(Path(path), kind)


def remove_owned(path: Path, kind: _core.OutputKind) -> list[str]:
    """Remove only what the output of `kind` in `path` wrote (`--overwrite`); an entry
    holding a file the command did not write is refused (InputError) before any goes."""
    return _core.remove_owned(Path(path), kind)


def refuse_not_written(
    path: Path, kind: _core.OutputKind, entries: Iterable[str], command: str, option: str = "--out"
) -> None:
    """ConfigError naming the first file inside `entries` (owned entries of the output
    of `kind` in `path`, about to be replaced) that `blurset <command>` did not write: a
    user's note in a gain or scene folder is named, never deleted with it."""
    for rel in entries:
        found = _core.not_written(Path(path), kind, rel)
        if found:
            more = f" (and {len(found) - 1} more)" if len(found) > 1 else ""
            raise ConfigError(
                f"{option} holds {found[0]}{more}, which blurset {command} did not write "
                f"and would delete with {rel}: move it out, then rerun (nothing was changed): "
                f"{path}"
            )


def refuse_links(path: Path, entries: Iterable[str], command: str, option: str = "--out") -> None:
    """ConfigError naming the first link on the way to `entries` (paths relative to the
    output `path` that `blurset <command>` is about to write or remove): it made none of
    them, and would write (or remove) through it wherever it points."""
    if link := _core.linked_entry(Path(path), list(entries)):
        raise ConfigError(
            f"{option}/{link} is a link, which blurset {command} did not make and would write "
            f"through: remove the link, or give another {option} (nothing was changed): {path}"
        )


def read_record(path: Path, record: str | None = None) -> Any:
    """A record blurset wrote, checked against its shape (InputError names the file and
    the field); `record` names it when the file is named otherwise."""
    return _core.read_record(Path(path), record)


def write_record(path: Path, value: Mapping[str, Any], record: str | None = None) -> None:
    """Write a record assembled here (dataset.json's start, noise_dataset.json,
    noise_scene.json, export.json, noise.json) through the core's type and schema,
    atomically; `record` names it when the file is named otherwise."""
    _core.write_record(Path(path), record or Path(path).name, value)


def record_schemas() -> dict[str, Any]:
    """The JSON Schema of every record blurset writes, by schema file name
    (`meta.schema.json` …): what `schemas/` in the repository holds."""
    return dict(_core.record_schemas())


def worker_schemas() -> dict[str, Any]:
    """The worker contract's JSON Schemas (dataset/wire.rs), by path under schemas/:
    `worker/request.schema.json` (what the builder sends a Blender worker) and
    `worker/reply.schema.json` (what it answers)."""
    return {
        f"worker/{stem.removeprefix('worker_')}.schema.json": schema
        for stem, schema in _core.worker_schemas()
    }


def write_schemas(folder: Path) -> list[Path]:
    """Write every record's JSON Schema, and the worker contract's, into `folder` (`make
    schemas`: the repository's schemas/ folder); returns the files."""
    import json

    out = []
    for name, schema in {**record_schemas(), **worker_schemas()}.items():
        (Path(folder) / name).parent.mkdir(parents=True, exist_ok=True)
        layout.write_text_atomic(Path(folder) / name, json.dumps(schema, indent=2) + "\n")
        out.append(Path(folder) / name)
    return out


def build_state(build: Path) -> _core.BuildState:
    """The complete settings of a build and why it is provisional (empty: finished)."""
    return _core.build_state(Path(build))


def finished_build(build: Path, option: str = "BUILD") -> _core.BuildState:
    """The state of a build that must be finished to be read (export, card, noise):
    InputError naming it, and how to finish it, when it is provisional."""
    if kind_of(build) is not OutputKind.BUILD:
        raise InputError(f"not a blurset build (no dataset.json): {build}")
    state = build_state(build)
    if state.provisional:
        raise InputError(
            f"{option} is a build that is not finished ({state.provisional[0]}"
            f"{'; …' if len(state.provisional) > 1 else ''}): let its run end, or rerun "
            f"`blurset build` with the same options to finish it: {build}"
        )
    damaged = damaged_settings(build, state.complete)
    if damaged:
        name, problem = damaged[0]
        raise InputError(
            f"{option} has a damaged setting ({name}: {problem}"
            f"{f'; and {len(damaged) - 1} more' if len(damaged) > 1 else ''}): rerun "
            f"`blurset build` with the same options to redo it (`blurset verify` lists "
            f"everything): {build}"
        )
    return state


def damaged_settings(build: Path, complete: list[str]) -> list[tuple[str, str]]:
    """(setting, what is wrong) of every complete setting of `build` that the cheap check
    of a rerun would redo (a missing image or level, a truncated pose file, a meta.json
    promising more views than the folder holds)."""
    out = []
    for name in complete:
        problem = layout.setting_problem(Path(build) / name)
        if problem is not None:
            out.append((name, problem))
    return out


def noise_mismatch(doc: dict, noise: Path, build: Path) -> str | None:
    """Why the noise output `noise` (its noise_dataset.json: `doc`) was not made from `build`,
    or None. Not the folder's name alone (two builds both named `build`): the build's
    seed, every setting it noised being a complete setting of the build, and one noised
    unit's poses_bounds.npy the same bytes as the build's (another build of the same
    objects has other views, sizes or poses)."""
    build = Path(build)
    name = build.resolve().name
    if doc.get("build") != name:
        return f"made from the build {doc.get('build')!r}, not from {name!r}"
    try:
        seed = read_record(build / layout.DATASET).get("seed")
    except (OSError, ValueError, InputError):
        seed = None
    if doc.get("build_seed") is not None and seed is not None and doc["build_seed"] != seed:
        return f"made from a build of seed {doc['build_seed']}, this one has seed {seed}"
    complete = set(_core.complete_settings(build))
    noised = sorted((doc.get("seeds") or {}).keys())
    foreign = [s for s in noised if s not in complete]
    if foreign:
        return f"it holds settings this build does not: {', '.join(foreign[:3])}"
    for s in noised:
        for level in sorted((doc.get("seeds") or {}).get(s) or {}):
            ours = build / s / level / layout.POSES_BOUNDS
            units = sorted((Path(noise) / s / level).glob("gain_*"))
            for u in units:
                theirs = u / layout.POSES_BOUNDS
                if theirs.is_file() and ours.is_file():
                    if theirs.read_bytes() != ours.read_bytes():
                        return (
                            f"{s}/{level}/{u.name}/{layout.POSES_BOUNDS} differs from the "
                            "build's: another build of the same name"
                        )
                    return None
    return None


def noise_of_build(noise: Path, build: Path, option: str = "--noise") -> dict:
    """noise_dataset.json of a finished `blurset noise BUILD` output made from `build`
    (`noise_mismatch`); InputError naming `option` and the folder otherwise."""
    noise = Path(noise)
    if kind_of(noise) is not OutputKind.NOISE:
        raise InputError(
            f"{option} is not a `blurset noise BUILD` output (noise_dataset.json): {noise}"
        )
    doc = read_record(noise / layout.NOISE_DATASET)
    why = noise_mismatch(doc, noise, build)
    if why is not None:
        raise InputError(f"{option} is not a noise output of this build ({why}): {noise}")
    if doc.get("counts") is None:
        raise InputError(
            f"{option} is not finished (a noise run is writing or was stopped): {noise}"
        )
    return doc


# What a lock file holds: the run that holds it, `pid N on host H` (`pid N` before the
# host was written), or nothing (a run killed before it wrote).
_HOLDER = re.compile(r"pid \d+(?: on host \S*)?\s*")


def open_lock(lock_path: Path) -> IO[str]:
    """Open (create) a lock file for reading and appending, never through a link: a link
    by that name (to a user's file outside the folder, or to nothing) would have blurset
    write who holds the lock into what it points to. Such a link, or a folder by that
    name, is an InputError naming it."""
    flags = os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_NOFOLLOW | os.O_CLOEXEC
    try:
        fd = os.open(lock_path, flags, 0o666)
    except OSError as e:
        if e.errno not in (errno.ELOOP, errno.EISDIR):
            raise
        raise _not_a_lock(lock_path, "a link" if e.errno == errno.ELOOP else "a folder") from None
    return os.fdopen(fd, "a+")


def _not_a_lock(lock_path: Path, what: str) -> InputError:
    return InputError(
        f"{lock_path} is {what}, not a lock file (blurset never writes a lock through a "
        "link); move it away"
    )


@contextlib.contextmanager
def flock_file(lock_path: Path, on_busy: Callable[[str], None] | None = None) -> Iterator[None]:
    """Hold an exclusive flock on `lock_path`, writing who holds it into the file. When
    another process holds it, `on_busy(holder)` runs first: it raises to refuse, or
    returns to wait. The file is removed on release; a waiter that then holds the
    removed file sees another inode and tries again."""
    while True:
        f = open_lock(lock_path)
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            holder = f.read().strip() or "another process"
            try:
                if on_busy is not None:
                    on_busy(holder)
                fcntl.flock(f, fcntl.LOCK_EX)
            except BaseException:
                f.close()
                raise
        try:
            same = os.fstat(f.fileno()).st_ino == os.lstat(lock_path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        f.close()
    f.seek(0)
    held = f.read()
    if held and not _HOLDER.fullmatch(held):
        # Not a lock any blurset run left (one says who held it): a user's file.
        f.close()
        raise InputError(
            f"{lock_path} is a file blurset did not write (its lock file holds who holds "
            "it); move it away"
        )
    try:
        f.seek(0)
        f.truncate()
        f.write(f"pid {os.getpid()} on host {socket.gethostname()}\n")
        f.flush()
        yield
    finally:
        lock_path.unlink(missing_ok=True)
        f.close()


@contextlib.contextmanager
def lock(path: Path, kind: _core.OutputKind, option: str = "--out") -> Iterator[None]:
    """Hold `kind`'s lock in the folder `path` (created if needed) for a whole run: a
    second writer of the same output is refused at once, naming who holds it."""
    path = Path(path)
    created = not path.exists()
    path.mkdir(parents=True, exist_ok=True)

    def refuse(holder: str) -> None:
        raise ConfigError(
            f"{option} is being written by another blurset run ({holder}): wait for it "
            f"to end, or give another {option}: {path}"
        )

    try:
        with flock_file(path / kind.lock_name, refuse):
            yield
    finally:
        if created:
            # A run that wrote nothing leaves nothing, not even the folder it made.
            with contextlib.suppress(OSError):
                path.rmdir()


def claim_report(path: Path, is_report: Callable[[Any], bool], option: str) -> None:
    """Refuse, before any work, a report file that would replace something else: `path`
    may be absent or hold a report `is_report` recognises (the command's own, from an
    earlier run); a folder, a build's meta.json, any other file is left alone, with a
    ConfigError naming `option` and the file."""
    path = Path(path)
    if not path.exists():
        return
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a folder; give the report's file name")
    try:
        doc = json.loads(path.read_bytes())
    except (OSError, ValueError):
        doc = None
    if doc is None or not is_report(doc):
        raise ConfigError(
            f"{option} {path}: the file exists and is not a report of this command; "
            "give another file name (nothing was replaced)"
        )


def write_marked_text(
    path: Path, text: str, *, command: str, force: bool = False, option: str = "--out"
) -> Path | None:
    """Write `text` to `path` with blurset's mark (atomically). A file there that
    `command` did not write, or that someone edited since, is replaced only with
    `force`, and then kept beside it as `<name>.bak`, whose path is returned;
    otherwise ConfigError names the file."""
    path = Path(path)
    owner = _core.text_owner(path, command)
    backup = None
    if owner in ("edited", "foreign"):
        what = (
            "was edited since blurset wrote it"
            if owner == "edited"
            else (f"was not written by blurset {command}")
        )
        if not force:
            raise ConfigError(
                f"{option} {path.name} {what}: keep it (give another {option}), or pass "
                f"--force to replace it (the old one is then kept beside it as {path.name}.bak): {path}"
            )
        backup = path.with_name(path.name + ".bak")
        n = 1
        while backup.exists():  # an older backup is the user's too
            backup = path.with_name(f"{path.name}.bak{n}")
            n += 1
        layout.write_bytes_atomic(backup, path.read_bytes())
    layout.write_text_atomic(path, _core.mark_text(text, command))
    return backup


# -- where an output may be: never over its inputs, never inside a build's setting -----


def refuse_overlap(out: Path, inputs: list[Path], option: str = "--out") -> None:
    """An output may not be, lie inside or contain any input: writing (or replacing with
    --overwrite) would destroy what it reads. ConfigError names both."""
    o = Path(out).resolve()
    for i in inputs:
        r = Path(i).resolve()
        if o == r:
            raise ConfigError(f"{option} is an input of this command: {out}")
        if o.is_relative_to(r):
            raise ConfigError(f"{option} lies inside the input {str(i)!r}: {out}")
        if r.is_relative_to(o):
            raise ConfigError(f"{option} contains the input {str(i)!r}: {out}")


def setting_of(path: Path) -> Path | None:
    """The build setting directory `path` lies in (a folder with meta.json whose parent
    is a build, by the output owner's one rule), or None."""
    p = Path(path).resolve()
    for d in [p, *p.parents]:
        if (d / layout.META).is_file() and kind_of(d.parent) is OutputKind.BUILD:
            return d
    return None


def refuse_inside_settings(out: Path, option: str = "--out", allow: tuple[str, ...] = ()) -> None:
    """Outputs of previews and statistics never go into a build's settings (they would
    replace dataset images or add files to an LLFF folder); `allow` names the files a
    setting may take at its top (e.g. preview.png)."""
    o = Path(out).resolve()
    s = setting_of(o if o.exists() else o.parent)
    if s is None or (o.parent == s and o.name in allow):
        return
    raise ConfigError(f"{option} lies inside the build setting {str(s)!r}: {out}")
