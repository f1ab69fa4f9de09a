"""Readers and writers for B-mode images, masks, contours and run records.

Read anything with :func:`read_sequence`; write results with the ``write_*``
functions, all atomic; give each run its own folder with :func:`output_folder`.
"""

from hifumotion._lazy import lazy_exports

# names → their modules, imported on first use (the readers pull SimpleITK, pydicom, OpenCV;
# a configuration's validation needs none of them)
_WHERE = {"atomic_path": "files", "check_output_folder": "files", "output_folder": "files", "write_text": "files",
          "load_initial_contours": "init_json", "read_init_json": "init_json", "SUPPORTED": "reader",
          "read_sequence": "reader", "read_contours_csv": "writers", "read_mask": "writers",
          "write_contours_csv": "writers", "write_contours_json": "writers", "write_json": "writers",
          "write_mask_png": "writers", "write_masks_nifti": "writers", "write_nifti": "writers",
          "write_png_stack": "writers", "write_sequence_nifti": "writers"}


__getattr__ = lazy_exports(__name__, _WHERE)
__all__ = sorted(_WHERE)
