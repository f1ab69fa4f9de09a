"""B-mode ultrasound simulation (:mod:`.bmode`) and segmentation phantoms (:mod:`.phantom`)."""

from hifumotion.imaging.bmode import BModeImage, BModeOptions, Scatterers, Transducer, log_compress, simulate_frame
from hifumotion.imaging.phantom import PRESETS, make_phantom, write_phantom

__all__ = ["BModeImage", "BModeOptions", "PRESETS", "Scatterers", "Transducer", "log_compress", "make_phantom",
           "simulate_frame", "write_phantom"]
