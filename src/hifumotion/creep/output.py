"""The fast path's frames for ParaView: the voxel mesh as hexahedra, with displacement (mm).

``frames/creep_0000.vtu`` … (unstructured grids of the voxels' corners, point data
``displacement_mm``), ``creep.pvd`` (the time index) and ``bar_pose.csv`` (s, mm);
written atomically, like the explicit path's frames.
"""

from __future__ import annotations

from pathlib import Path


from hifumotion.io.files import atomic_path, write_text
from hifumotion.particles.output import write_pvd


def write_frames(folder: str | Path, sim, mesh, result, every: int = 1) -> Path:
    """Write every ``every``-th frame of a :class:`~.integrate.CreepResult`; return the PVD's path."""
    import meshio

    folder = Path(folder)
    (folder / "frames").mkdir(parents=True, exist_ok=True)
    entries = []
    for k in range(0, len(result.times_s), every):
        grid = meshio.Mesh(result.nodes_mm[k], [("hexahedron", mesh.elements)],
                           point_data={"displacement_mm": result.nodes_mm[k] - mesh.nodes_mm})
        path = folder / "frames" / f"creep_{k:04d}.vtu"
        with atomic_path(path) as tmp:
            meshio.write(tmp, grid, file_format="vtu", binary=True)
        entries.append((float(result.times_s[k]), path.relative_to(folder)))
    lines = ["time_s,x_mm,y_mm,z_mm"] + [f"{t:.6g},{b[0]:.6g},{b[1]:.6g},{b[2]:.6g}"
                                         for t, b in zip(sim.times_s, sim.bar_centre_mm)]
    write_text(folder / "bar_pose.csv", "\n".join(lines) + "\n")
    return write_pvd(folder / "creep.pvd", entries)


__all__ = ["write_frames"]
