"""What every result shares on its way out: plain JSON values, and the result base.

:class:`Result` is the base of the diagnosis results (``to_dict``, ``to_json``, ``save``);
:func:`jsonable` is the one conversion of a result's numbers to JSON: numpy scalars
become Python numbers, arrays lists, and a number that is not finite becomes ``null``
(JSON has no NaN or infinity; a reader meets a clear "no value", never an invalid file).
"""

from __future__ import annotations

import json
import math

import numpy as np


def jsonable(x):
    """``x`` with every mapping, sequence, array and numpy scalar turned into JSON values."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


class Result:
    """What every diagnosis result shares: its numbers as a dict, that dict as JSON, saved.

    A subclass gives :meth:`to_dict` (plain numbers, lists and dicts; numpy values are
    converted here) and, for its page, :meth:`report`.
    """

    def to_dict(self) -> dict:  # pragma: no cover - every result defines it
        raise NotImplementedError

    def to_json(self, **kwargs) -> str:
        """:meth:`to_dict` as JSON (``kwargs`` as :func:`json.dumps`'; non-finite numbers are null)."""
        return json.dumps(jsonable(self.to_dict()), **kwargs)

    def save(self, path, *, overwrite: bool = False):
        """Write :meth:`to_json` (indented) to ``path`` atomically; an existing file only with
        ``overwrite``.  Returns the path."""
        from .outputs import atomic_write_text

        return atomic_write_text(path, self.to_json(indent=2) + "\n", overwrite=overwrite)
