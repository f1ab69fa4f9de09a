"""The observed experiment: the data a device's user has, shared by its writers and readers.

Neither the synthetic twin (:mod:`hifumotion.experiment`, which writes it) nor the
estimation (:mod:`hifumotion.estimation`, which reads it) owns this package; the real-data
path goes from a user's files through here to the fit without touching the twin.

- :mod:`.setup` — :class:`Setup`, the typed, versioned ``setup.json``;
- :mod:`.folder` — :class:`Observed`, :func:`load_observed`, :func:`write_observed`;
- :mod:`.boundary` — :func:`shift_boundary`, a segmentation's boundary moved by the
  imaging system's measured offset.
"""

from hifumotion.observed.boundary import shift_boundary
from hifumotion.observed.folder import Observed, load_observed, write_observed
from hifumotion.observed.setup import (SCHEMA_VERSION, BarSetup, ImagingGeometry, PushSchedule, Setup, TankSetup,
                                       read_setup, write_setup)

__all__ = ["Observed", "load_observed", "write_observed", "Setup", "ImagingGeometry", "TankSetup", "BarSetup",
           "PushSchedule", "SCHEMA_VERSION", "read_setup", "write_setup", "shift_boundary"]
