"""VTK XML writers for ParaView and 3D Slicer: PolyData (.vtp) surfaces.

trimesh writes STL and PLY but not VTK's XML formats; a PolyData file is a
short XML document, written here directly (ASCII, so it can be read by eye).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from hifumotion.io import write_text


def _data_array(name: str, values: np.ndarray, kind: str) -> str:
    arr = np.asarray(values)
    comps = 1 if arr.ndim == 1 else arr.shape[1]
    text = " ".join(f"{v:.7g}" if kind.startswith("Float") else str(int(v)) for v in arr.ravel())
    return (f'<DataArray type="{kind}" Name="{name}" NumberOfComponents="{comps}" format="ascii">'
            f"{text}</DataArray>")


def write_vtp(path: str | Path, vertices: np.ndarray, triangles: np.ndarray,
              point_data: Mapping[str, np.ndarray] | None = None) -> Path:
    """A triangle surface as VTK XML PolyData: ``vertices (N, 3)`` in mm, ``triangles (M, 3)`` indices."""
    v = np.asarray(vertices, float)
    f = np.asarray(triangles, np.int64)
    pd = "".join(_data_array(k, np.asarray(a, float), "Float32") for k, a in (point_data or {}).items())
    xml = (
        '<?xml version="1.0"?>\n<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">\n<PolyData>\n'
        f'<Piece NumberOfPoints="{len(v)}" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="{len(f)}">\n'
        f"<PointData>{pd}</PointData>\n"
        f"<Points>{_data_array('Points', v, 'Float32')}</Points>\n"
        f"<Polys>{_data_array('connectivity', f.ravel(), 'Int64')}"
        f"{_data_array('offsets', 3 * np.arange(1, len(f) + 1), 'Int64')}</Polys>\n"
        "</Piece>\n</PolyData>\n</VTKFile>\n"
    )
    return write_text(path, xml)
