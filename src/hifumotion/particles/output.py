"""Simulation output for ParaView: per-frame VTU point clouds, a PVD index, the bar's pose.

Positions are written in mm (the project's interface unit), velocities in
mm/s, pressure in Pa, strain dimensionless. Files are written with meshio
(binary VTU, one ``vertex`` cell per particle) through a temporary name, so an
interrupted run never leaves a half-written frame. Open ``frames.pvd`` in
ParaView to play the run; ``tank.vtu`` holds the (static) walls.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hifumotion.io.files import atomic_path, write_text
from hifumotion.particles.system import ParticleSystem

M_TO_MM = 1000.0


def write_points_vtu(path: str | Path, points_mm: np.ndarray, point_data: dict[str, np.ndarray]) -> Path:
    """A point cloud as a binary VTU file (one vertex cell per point)."""
    import meshio

    pts = np.ascontiguousarray(points_mm, dtype=np.float64)
    cells = [("vertex", np.arange(len(pts), dtype=np.int64)[:, None])]
    mesh = meshio.Mesh(pts, cells, point_data={k: np.ascontiguousarray(v) for k, v in point_data.items()})
    path = Path(path)
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="vtu", binary=True)
    return path


def write_pvd(path: str | Path, entries) -> Path:
    """A ParaView collection: ``entries`` are ``(time_s, file relative to the PVD)``."""
    rows = "\n".join(f'    <DataSet timestep="{t:.9g}" group="" part="0" file="{n}"/>' for t, n in entries)
    return write_text(path, '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" '
                      'byte_order="LittleEndian">\n'
                      f"  <Collection>\n{rows}\n  </Collection>\n</VTKFile>\n")


def frame_data(system: ParticleSystem, pressure_pa: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
    """Points (mm) and per-point data of the moving particles (water, tissue, bar)."""
    n = system.n_moving
    phase = system.phase[:n].astype(np.int32)
    pressure = np.zeros(n)
    if pressure_pa is not None:
        pressure[:] = pressure_pa[:n]
    else:
        pressure[: system.n_fluid] = system.pressure
    strain = np.zeros(n)
    displacement = np.zeros((n, 3))
    sl = system.tissue_slice
    strain[sl] = system.strain
    displacement[sl] = (system.x[sl] - system.tissue_rest) * M_TO_MM
    data = {
        "type": phase,
        "velocity_mm_s": system.v[:n] * M_TO_MM,
        "pressure_pa": pressure,
        "strain": strain,
        "displacement_mm": displacement,
    }
    return system.x[:n] * M_TO_MM, data


class FrameWriter:
    """Writes ``frames/frame_0000.vtu`` …, ``frames.pvd``, ``tank.vtu`` and ``bar_pose.csv``."""

    def __init__(self, folder: str | Path, system: ParticleSystem):
        self.folder = Path(folder)
        (self.folder / "frames").mkdir(parents=True, exist_ok=True)
        self.entries: list[tuple[float, str]] = []
        self.pose_rows: list[str] = []
        if system.n_wall:
            walls = system.slice_of(3)
            write_points_vtu(self.folder / "tank.vtu", system.x[walls] * M_TO_MM,
                             {"type": system.phase[walls].astype(np.int32)})

    def write(self, system: ParticleSystem, pressure_pa: np.ndarray | None = None) -> Path:
        k = len(self.entries)
        name = f"frames/frame_{k:04d}.vtu"
        points, data = frame_data(system, pressure_pa)
        write_points_vtu(self.folder / name, points, data)
        self.entries.append((system.time_s, name))
        for b in system.bodies:
            c = b.centre_m * M_TO_MM
            v = b.velocity_m_s * M_TO_MM
            q = b.orientation
            f = b.last_particle_force_n
            self.pose_rows.append(
                f"{k},{system.time_s:.6g},{b.name},{c[0]:.6g},{c[1]:.6g},{c[2]:.6g},"
                f"{q[0]:.8g},{q[1]:.8g},{q[2]:.8g},{q[3]:.8g},{v[0]:.6g},{v[1]:.6g},{v[2]:.6g},"
                f"{b.force_n(system.time_s):.6g},{f[0]:.6g},{f[1]:.6g},{f[2]:.6g}")
        self.finish()
        return self.folder / name

    def finish(self) -> None:
        """(Re)write the PVD index and the pose CSV for the frames so far."""
        write_pvd(self.folder / "frames.pvd", self.entries)
        header = ("frame,time_s,body,centre_x_mm,centre_y_mm,centre_z_mm,q_w,q_x,q_y,q_z,"
                  "velocity_x_mm_s,velocity_y_mm_s,velocity_z_mm_s,applied_force_n,"
                  "contact_force_x_n,contact_force_y_n,contact_force_z_n")
        write_text(self.folder / "bar_pose.csv", header + "\n" + "\n".join(self.pose_rows) + "\n")


__all__ = ["FrameWriter", "write_points_vtu", "write_pvd", "frame_data"]
