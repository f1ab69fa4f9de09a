"""``hifumotion reconstruct``: the 3D tissue model from a sweep of segmented slices."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer

from hifumotion.cli.app import app, parse_spacing, positive
from hifumotion.console import console, log
from hifumotion.errors import InputError


@app.command()
def reconstruct(
    sweep: Path = typer.Argument(..., help="Masks of the sweep's slices: a folder of mask PNGs, a NIfTI/MHA/NRRD volume or DICOM series."),
    slice_spacing: Optional[float] = typer.Option(None, "--slice-spacing", callback=positive, help="Gap between slices in mm (when the file has no positions)."),
    spacing: Optional[str] = typer.Option(None, "--spacing", help="In-plane pixel size in mm: '0.2' or 'row,col'. Overrides the file."),
    voxel: Optional[float] = typer.Option(None, "--voxel", callback=positive, help="Voxel size of the volume in mm (default from the sweep)."),
    particle_spacing: Optional[float] = typer.Option(None, "--particle-spacing", callback=positive, help="Also write particles on a lattice of this spacing (mm)."),
    output: Path = typer.Option(..., "--output", "-o", help="New output folder."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Reconstruct the tissue: volume (NIfTI), surface (STL, PLY, VTP) and optionally particles (CSV)."""
    from hifumotion.io import output_folder, read_sequence, write_json, write_text
    from hifumotion.io.writers import check_binary
    from hifumotion.reconstruction import reconstruct as run
    from hifumotion.run_info import RunRecord

    seq = read_sequence(sweep, parse_spacing(spacing))
    if slice_spacing is not None:
        if not slice_spacing > 0:
            raise InputError("expected a positive gap in mm", "--slice-spacing")
        positions = np.arange(seq.n_frames) * float(slice_spacing)
    elif seq.slice_positions_mm is not None:
        positions = seq.slice_positions_mm
    else:
        raise InputError("has no slice positions; give --slice-spacing", sweep)
    check_binary(seq.frames, sweep)
    if not seq.spacing_known and spacing is None:
        log.warning("%s carries no pixel size; using 1 mm (give --spacing)", sweep)
    # a mask: 0 and one other value (checked above), whatever that value is — 1 in a label map
    # (hifumotion's own truth/sweep.nii.gz), 255 in a PNG
    masks = seq.frames > 0
    record = RunRecord("reconstruct", config={"sweep": str(sweep), "spacing_mm": list(seq.spacing_mm),
                                              "slice_positions_mm": [float(p) for p in positions],
                                              "voxel_mm": voxel, "particle_spacing_mm": particle_spacing})
    with output_folder(output, overwrite, inputs=(sweep,)) as out:
        with record.stage("reconstruct"):
            try:
                rec = run(masks, seq.spacing_mm, positions, voxel_mm=voxel)
            except InputError as exc:   # name the option or the file the user gave
                raise InputError(exc.reason, "--voxel" if exc.source == "voxel size" else sweep) from None
        with record.stage("write"):
            files = rec.write(out)
            summary = {"volume_mm3": rec.volume_mm3, "surface_area_mm2": float(rec.mesh.area),
                       "watertight": bool(rec.mesh.is_watertight), "voxel_mm": rec.voxel_mm,
                       "vertices": int(len(rec.mesh.vertices)), "faces": int(len(rec.mesh.faces)),
                       "notes": rec.notes, "files": {k: v.name for k, v in files.items()}}
            if particle_spacing:
                try:
                    p = rec.particles(particle_spacing)
                except InputError as exc:
                    raise InputError(exc.reason, "--particle-spacing") from None
                rows = "\n".join(f"{x:.5f},{y:.5f},{z:.5f},{v:.6g},{int(s)}"
                                 for (x, y, z), v, s in zip(p.positions_mm, p.volume_mm3, p.surface))
                write_text(out / "particles.csv", "x_mm,y_mm,z_mm,volume_mm3,surface\n" + rows + "\n")
                summary["particles"] = len(p)
            write_json(out / "reconstruction.json", summary)
        record.extra["summary"] = summary
        record.write(out)
    for note in rec.notes:
        log.info("%s", note)
    log.info("volume %.1f mm³, %d triangles, watertight: %s", rec.volume_mm3, len(rec.mesh.faces), rec.mesh.is_watertight)
    console.print(f"results in {output.resolve()} (open tissue.vtp in ParaView, tissue_volume.nii.gz in 3D Slicer)",
                  highlight=False)
