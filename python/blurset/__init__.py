"""blurset: multi-view datasets with realistic degradations for generalizable NeRFs."""

from blurset._core import __version__

__all__ = ["__version__"]
