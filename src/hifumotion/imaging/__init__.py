"""B-mode ultrasound simulation (:mod:`.bmode`) and segmentation phantoms (:mod:`.phantom`)."""

from hifumotion.imaging.bmode import (BModeImage, BModeOptions, Scatterers, Transducer, echogenicity_sampler,
                                     log_compress, simulate_frame, simulate_image)
from hifumotion.imaging.phantom import PRESETS, make_phantom, write_phantom

__all__ = ["BModeImage", "BModeOptions", "PRESETS", "Scatterers", "Transducer", "echogenicity_sampler", "log_compress",
           "make_phantom", "simulate_frame", "simulate_image", "write_phantom"]
