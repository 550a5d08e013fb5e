"""Exceptions raised by blurset; every one carries a one-line message naming the file or option."""

from blurset._core import BlursetError, ImageError, PoseFormatError


class ConfigError(BlursetError):
    """A bad option or config value; the message names the option."""


class InputError(BlursetError):
    """Bad input data (missing file, wrong shape, mismatched sizes); the message names the file."""


__all__ = ["BlursetError", "ConfigError", "ImageError", "InputError", "PoseFormatError"]
