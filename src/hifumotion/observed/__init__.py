"""The observed experiment: the data a device's user has, shared by its writers and readers.

Neither the synthetic twin (:mod:`hifumotion.experiment`, which writes it) nor the
estimation (:mod:`hifumotion.estimation`, which reads it) owns this package; the real-data
path goes from a user's files through here to the fit without touching the twin.

- :mod:`.setup` — :class:`Setup`, the typed, versioned ``setup.json``;
- :mod:`.folder` — :class:`Observed`, :func:`load_observed`, :func:`read_initial_contour`, :func:`write_observed`;
- :mod:`.boundary` — :func:`shift_boundary`, a segmentation's boundary moved by the
  imaging system's measured offset.
"""

from hifumotion._lazy import lazy_exports

# names → their modules, imported on first use (the folder's reader pulls the image stack)
_WHERE = {"shift_boundary": "boundary", "Observed": "folder", "load_observed": "folder", "write_observed": "folder",
          "read_initial_contour": "folder",
          "SCHEMA_VERSION": "setup", "BarSetup": "setup", "ImagingGeometry": "setup", "PushSchedule": "setup",
          "Setup": "setup", "TankSetup": "setup", "read_setup": "setup", "write_setup": "setup"}


__getattr__ = lazy_exports(__name__, _WHERE)
__all__ = sorted(_WHERE)
