"""Readers and writers for B-mode images, masks, contours and run records.

Read anything with :func:`read_sequence`; write results with the ``write_*``
functions, all atomic; give each run its own folder with :func:`output_folder`.
"""

from hifumotion.io.files import atomic_path, check_output_folder, output_folder, write_text
from hifumotion.io.init_json import load_initial_contours, read_init_json
from hifumotion.io.reader import SUPPORTED, read_sequence
from hifumotion.io.writers import (
    read_contours_csv,
    read_mask,
    write_contours_csv,
    write_contours_json,
    write_json,
    write_mask_png,
    write_masks_nifti,
    write_nifti,
    write_png_stack,
    write_sequence_nifti,
)

__all__ = [
    "SUPPORTED",
    "atomic_path",
    "check_output_folder",
    "load_initial_contours",
    "output_folder",
    "read_contours_csv",
    "read_init_json",
    "read_mask",
    "read_sequence",
    "write_contours_csv",
    "write_contours_json",
    "write_json",
    "write_mask_png",
    "write_masks_nifti",
    "write_nifti",
    "write_png_stack",
    "write_sequence_nifti",
    "write_text",
]
