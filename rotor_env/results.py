"""What every result shares on its way out: plain JSON values.

:func:`jsonable` is the one conversion of a result's numbers to JSON: numpy scalars
become Python numbers, arrays lists, and a number that is not finite becomes ``null``
(JSON has no NaN or infinity; a reader meets a clear "no value", never an invalid file).
"""

from __future__ import annotations

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
