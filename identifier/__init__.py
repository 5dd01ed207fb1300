"""identifier — time- and order-recursive QR least squares with significance tests.

Generic numerics (numpy, scipy, numba): regressors, columns and named groups of
columns.  It knows nothing about rotors.

>>> import numpy as np
>>> from identifier import RecursiveQR
>>> est = RecursiveQR(2)
>>> _ = est.update_many(np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]), np.array([1.0, 2.0, 3.0]))
>>> est.coefficients().round(12).tolist()
[1.0, 2.0]
"""

from .recursive_qr import History, RecursiveQR
from .significance import (
    InformationCriteria,
    SignificanceTable,
    f_log10_sf,
    information_criteria,
    nested_f,
    nested_tests,
    partial_f,
)

__all__ = [
    "History",
    "InformationCriteria",
    "RecursiveQR",
    "SignificanceTable",
    "f_log10_sf",
    "information_criteria",
    "nested_f",
    "nested_tests",
    "partial_f",
]
