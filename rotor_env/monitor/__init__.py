"""On-line monitoring: a measurement stream in, the identified model and alarms out (issue 15).

:class:`Monitor` (Python API, state saved to ``.npz``), :class:`StreamReader` (chunks of a
file, a followed file or stdin), the sequential test's design in :mod:`.detector`, the
command ``rotor-id monitor`` in :mod:`.cli`.
"""

from .core import Monitor, MonitorConfig
from .detector import CusumDesign, cusum_arl0, cusum_threshold, simulate_arl
from .stream import StreamReader, iter_chunks

__all__ = ["CusumDesign", "Monitor", "MonitorConfig", "StreamReader", "cusum_arl0", "cusum_threshold",
           "iter_chunks", "simulate_arl"]
