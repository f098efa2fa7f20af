"""The dict a view or a crop comes as. Its colour channel is `color`, the word the dataset
uses everywhere (the `color_png` column, `ViewRow::color()` and the trainer's `Batch.color`
in Rust); the key `render`, its earlier name, still reads it with a DeprecationWarning."""

from __future__ import annotations

import warnings

#: Old key -> the key that holds its value now.
RENAMED = {"render": "color"}


class View(dict):
    """A plain dict of one view's arrays and camera, where a renamed key still reads its new
    entry (through `view[key]` only: `in`, `get` and iteration see the new names)."""

    __slots__ = ()

    def __missing__(self, key):
        new = RENAMED.get(key)
        if new is None or new not in self:
            raise KeyError(key)
        warnings.warn(
            f"view[{key!r}] is now view[{new!r}]; the old key will go in a later release",
            DeprecationWarning,
            stacklevel=2,
        )
        return self[new]
