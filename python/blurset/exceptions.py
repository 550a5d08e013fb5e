"""Exceptions raised by blurset; every one carries a one-line message naming the file or option."""

from blurset._core import BlursetError, ImageError, InputError, PoseFormatError


class ConfigError(BlursetError):
    """A bad option or config value; the message names the option."""


# InputError (bad input data: missing file, wrong shape, mismatched sizes; the message
# names the file) is defined in rust/py/src/error.rs, so blurset-core raises it too.


__all__ = [
    "BlursetError",
    "ConfigError",
    "ImageError",
    "InputError",
    "PoseFormatError",
    "reason_of",
]


def reason_of(e: BaseException) -> str:
    """What went wrong, without the file it happened to: errors from blurset-core carry
    `reason` and `path` as fields (never parse the message for them)."""
    reason = getattr(e, "reason", None)
    return str(reason) if reason else " ".join(str(e).split())
