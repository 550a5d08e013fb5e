"""Exceptions raised by blurset; every one carries a one-line message naming the file or option."""

from blurset._core import BlursetError, ImageError, InputError, PoseFormatError


class ConfigError(BlursetError):
    """A bad option or config value; the message names the option."""


# InputError (bad input data: missing file, wrong shape, mismatched sizes; the message
# names the file) is defined in rust/py/src/error.rs, so blurset-core raises it too.


__all__ = ["BlursetError", "ConfigError", "ImageError", "InputError", "PoseFormatError"]
