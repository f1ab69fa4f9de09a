"""Numba kernels of the level-set core. All work is confined to a narrow band or a bounding box.

Conventions: ``phi`` is a float32 ``(H, W)`` array, positive inside the contour,
a signed distance in pixels within ``±width`` of the zero level and clamped to
``±(width + 1)`` beyond. A band is an ``(N, 2)`` int32 array of ``(row, col)``.
A segment is ``(x0, y0, x1, y1)`` in pixel coordinates (x = column).
"""

from __future__ import annotations

import numpy as np
from numba import njit

# --------------------------------------------------------------------------- interface geometry


@njit(cache=True, inline="always")
def _cross(a: float, b: float) -> float:
    """Fraction along an edge from a (value ``a``) to b where the linear interpolant crosses 0."""
    return a / (a - b)


@njit(cache=True, inline="always")
def _crossed(phi, i, j):
    """Whether the zero level crosses the cell with top-left pixel (i, j): a cheap test that
    spares most cells of a box the full marching-squares case analysis."""
    a = phi[i, j] > 0
    return a != (phi[i, j + 1] > 0) or a != (phi[i + 1, j + 1] > 0) or a != (phi[i + 1, j] > 0)


@njit(cache=True, inline="always")
def _cell_segments(phi, i, j, segs, pts):
    """Marching-squares segments of the cell with top-left pixel (i, j) into ``segs``; returns their count."""
    a = phi[i, j]          # top-left     (x=j,   y=i)
    b = phi[i, j + 1]      # top-right    (x=j+1, y=i)
    c = phi[i + 1, j + 1]  # bottom-right (x=j+1, y=i+1)
    d = phi[i + 1, j]      # bottom-left  (x=j,   y=i+1)
    code = (a > 0) * 1 + (b > 0) * 2 + (c > 0) * 4 + (d > 0) * 8
    if code == 0 or code == 15:
        return 0
    # crossing points on the four edges (only valid where the edge changes sign)
    tx = j + _cross(a, b) if (a > 0) != (b > 0) else 0.0
    ty = float(i)
    rx = float(j + 1)
    ry = i + _cross(b, c) if (b > 0) != (c > 0) else 0.0
    bx = j + _cross(d, c) if (d > 0) != (c > 0) else 0.0
    by = float(i + 1)
    lx = float(j)
    ly = i + _cross(a, d) if (a > 0) != (d > 0) else 0.0
    if code == 5 or code == 10:  # saddle
        centre = 0.25 * (a + b + c + d)
        if (centre > 0) == (code == 5):
            # a and c connected: separate b's and d's corners
            segs[0, 0], segs[0, 1], segs[0, 2], segs[0, 3] = tx, ty, rx, ry
            segs[1, 0], segs[1, 1], segs[1, 2], segs[1, 3] = bx, by, lx, ly
        else:
            segs[0, 0], segs[0, 1], segs[0, 2], segs[0, 3] = tx, ty, lx, ly
            segs[1, 0], segs[1, 1], segs[1, 2], segs[1, 3] = rx, ry, bx, by
        return 2
    m = 0
    if (a > 0) != (b > 0):
        pts[m, 0], pts[m, 1] = tx, ty
        m += 1
    if (b > 0) != (c > 0):
        pts[m, 0], pts[m, 1] = rx, ry
        m += 1
    if (d > 0) != (c > 0) and m < 2:
        pts[m, 0], pts[m, 1] = bx, by
        m += 1
    if (a > 0) != (d > 0) and m < 2:
        pts[m, 0], pts[m, 1] = lx, ly
        m += 1
    segs[0, 0], segs[0, 1], segs[0, 2], segs[0, 3] = pts[0, 0], pts[0, 1], pts[1, 0], pts[1, 1]
    return 1


@njit(cache=True)
def _append(out, n, segs, k):
    for s in range(k):
        if n == out.shape[0]:
            bigger = np.empty((out.shape[0] * 2, 4))
            bigger[:n] = out
            out = bigger
        out[n] = segs[s]
        n += 1
    return out, n


@njit(cache=True)
def interface_segments(phi, r0, r1, c0, c1):
    """Marching squares on the 0 level of ``phi`` within rows ``r0:r1`` and cols ``c0:c1``.

    Inside is ``phi > 0``. Returns a ``(S, 4)`` float64 array of segments
    ``(x0, y0, x1, y1)``. Saddle cells are resolved by the cell-centre average.
    """
    h, w = phi.shape
    r1 = min(r1, h - 1)
    c1 = min(c1, w - 1)
    out = np.empty((64, 4))
    segs = np.empty((2, 4))
    pts = np.empty((2, 2))
    n = 0
    for i in range(max(r0, 0), r1):
        for j in range(max(c0, 0), c1):
            if _crossed(phi, i, j):
                k = _cell_segments(phi, i, j, segs, pts)
                out, n = _append(out, n, segs, k)
    return out[:n]


@njit(cache=True)
def interface_segments_near(phi, band, stamp, tag):
    """Marching squares only in the cells that have a corner in ``band``.

    After a narrow-band update only band pixels changed, and a cell the zero
    level crossed before had a corner within the band, so these cells hold
    every crossing. ``stamp`` (int64, image-sized) marks visited cells with ``tag``.
    """
    h, w = phi.shape
    out = np.empty((64, 4))
    segs = np.empty((2, 4))
    pts = np.empty((2, 2))
    n = 0
    for q in range(band.shape[0]):
        for di in range(-1, 1):
            for dj in range(-1, 1):
                i = band[q, 0] + di
                j = band[q, 1] + dj
                if i < 0 or j < 0 or i >= h - 1 or j >= w - 1 or stamp[i, j] == tag:
                    continue
                stamp[i, j] = tag
                if _crossed(phi, i, j):
                    k = _cell_segments(phi, i, j, segs, pts)
                    out, n = _append(out, n, segs, k)
    return out[:n]


@njit(cache=True, fastmath=True)
def redistance_box(phi, segments, width, r0, r1, c0, c1):
    """Replace ``phi`` in rows ``r0:r1``, cols ``c0:c1`` by the signed distance to ``segments``.

    The sign (``phi > 0`` inside) is kept; magnitudes become the exact distance to
    the nearest segment where it is below ``width`` px, else ``width + 1``.
    Pixels outside the box are left unchanged (they are already clamped far values).
    """
    h, w = phi.shape
    r0, c0 = max(r0, 0), max(c0, 0)
    r1, c1 = min(r1, h), min(c1, w)
    far = width + 1.0
    for i in range(r0, r1):
        for j in range(c0, c1):
            v = phi[i, j]
            if v > 0:
                phi[i, j] = far
            else:
                phi[i, j] = -far
    limit2 = width * width
    for s in range(segments.shape[0]):
        x0, y0, x1, y1 = segments[s, 0], segments[s, 1], segments[s, 2], segments[s, 3]
        dx, dy = x1 - x0, y1 - y0
        len2 = dx * dx + dy * dy
        i_lo = max(int(np.floor(min(y0, y1) - width)), r0)
        i_hi = min(int(np.ceil(max(y0, y1) + width)), r1 - 1)
        j_lo = max(int(np.floor(min(x0, x1) - width)), c0)
        j_hi = min(int(np.ceil(max(x0, x1) + width)), c1 - 1)
        for i in range(i_lo, i_hi + 1):
            for j in range(j_lo, j_hi + 1):
                t = 0.0
                if len2 > 0:
                    t = ((j - x0) * dx + (i - y0) * dy) / len2
                    t = min(max(t, 0.0), 1.0)
                px = x0 + t * dx - j
                py = y0 + t * dy - i
                d2 = px * px + py * py
                if d2 < limit2:
                    cur = phi[i, j]
                    a = abs(cur)
                    if d2 < a * a:
                        d = np.sqrt(d2)
                        phi[i, j] = d if cur > 0 else -d
    return phi


# --------------------------------------------------------------------------- band and derivatives


@njit(cache=True)
def band_points(phi, limit, r0, r1, c0, c1):
    """``(N, 2)`` int32 ``(row, col)`` of the pixels of the box with ``|phi| <= limit``."""
    h, w = phi.shape
    r0, c0 = max(r0, 0), max(c0, 0)
    r1, c1 = min(r1, h), min(c1, w)
    n = 0
    for i in range(r0, r1):
        for j in range(c0, c1):
            if abs(phi[i, j]) <= limit:
                n += 1
    out = np.empty((n, 2), np.int32)
    k = 0
    for i in range(r0, r1):
        for j in range(c0, c1):
            if abs(phi[i, j]) <= limit:
                out[k, 0] = i
                out[k, 1] = j
                k += 1
    return out


@njit(cache=True, inline="always")
def _at(a, i, j):
    h, w = a.shape
    return a[min(max(i, 0), h - 1), min(max(j, 0), w - 1)]


@njit(cache=True, parallel=False)
def curvature(phi, band):
    """Mean curvature ``div(∇φ/|∇φ|)`` at band points (central differences), clamped to ±1/px."""
    n = band.shape[0]
    out = np.empty(n)
    for k in range(n):
        i, j = band[k, 0], band[k, 1]
        c = _at(phi, i, j)
        px = 0.5 * (_at(phi, i, j + 1) - _at(phi, i, j - 1))
        py = 0.5 * (_at(phi, i + 1, j) - _at(phi, i - 1, j))
        pxx = _at(phi, i, j + 1) - 2 * c + _at(phi, i, j - 1)
        pyy = _at(phi, i + 1, j) - 2 * c + _at(phi, i - 1, j)
        pxy = 0.25 * (_at(phi, i + 1, j + 1) - _at(phi, i + 1, j - 1) - _at(phi, i - 1, j + 1) + _at(phi, i - 1, j - 1))
        g2 = px * px + py * py
        if g2 < 1e-12:
            out[k] = 0.0
            continue
        kappa = (pxx * py * py - 2 * px * py * pxy + pyy * px * px) / (g2 ** 1.5)
        out[k] = min(max(kappa, -1.0), 1.0)
    return out


@njit(cache=True)
def geodesic_terms(phi, band, g, gx, gy, alpha):
    """Eq. 7's geodesic bracket at band points: ``g|∇φ|κ + ∇g·∇φ + α g|∇φ|``.

    ``alpha`` holds the balloon weight of each band point (a constant array for
    the paper's α).

    The curvature part uses central differences; the advection ``∇g·∇φ`` and
    the balloon ``α g |∇φ|`` are hyperbolic and use Godunov upwind differences
    (Osher & Sethian), so the scheme is stable with a CFL step.
    """
    n = band.shape[0]
    kappa = curvature(phi, band)
    out = np.empty(n)
    for k in range(n):
        i, j = band[k, 0], band[k, 1]
        c = _at(phi, i, j)
        dxm = c - _at(phi, i, j - 1)
        dxp = _at(phi, i, j + 1) - c
        dym = c - _at(phi, i - 1, j)
        dyp = _at(phi, i + 1, j) - c
        # |∇φ| upwinded for an outward (α > 0 grows φ) or inward balloon
        a = alpha[k]
        if a >= 0:
            grad = np.sqrt(max(dxm, 0.0) ** 2 + min(dxp, 0.0) ** 2 + max(dym, 0.0) ** 2 + min(dyp, 0.0) ** 2)
        else:
            grad = np.sqrt(min(dxm, 0.0) ** 2 + max(dxp, 0.0) ** 2 + min(dym, 0.0) ** 2 + max(dyp, 0.0) ** 2)
        # advection φ_t = ∇g·∇φ  ⇔  φ_t + (−∇g)·∇φ = 0: velocity v = −∇g, upwind on v
        vx, vy = -gx[i, j], -gy[i, j]
        adv_x = dxm if vx > 0 else dxp
        adv_y = dym if vy > 0 else dyp
        central = np.sqrt((0.5 * (dxm + dxp)) ** 2 + (0.5 * (dym + dyp)) ** 2)
        out[k] = g[i, j] * central * kappa[k] - (vx * adv_x + vy * adv_y) + a * g[i, j] * grad
    return out


# --------------------------------------------------------------------------- local (disk) statistics


@njit(cache=True)
def disk_half_widths(radius):
    """Half-width of the digital disk of ``radius`` px in each row offset ``-r … r``."""
    r = int(np.floor(radius))
    hw = np.empty(2 * r + 1, np.int64)
    for d in range(-r, r + 1):
        hw[d + r] = int(np.floor(np.sqrt(max(radius * radius - d * d, 0.0))))
    return hw


@njit(cache=True)
def row_prefix(a, r0, r1, c0, c1):
    """Row-wise prefix sums of ``a[r0:r1, c0:c1]`` with a leading zero column, as ``(rows, cols+1, 1)``:
    ``P[:, k, 0] = Σ a[:, c0:c0+k]``."""
    out = np.zeros((r1 - r0, c1 - c0 + 1, 1))
    for i in range(r0, r1):
        s = 0.0
        for j in range(c0, c1):
            s += a[i, j]
            out[i - r0, j - c0 + 1, 0] = s
    return out


@njit(cache=True, fastmath=True)
def disk_sums(prefixes, band, hw, r0, c0, h, w):
    """Sums of several arrays over the disk around each band point, from their row prefix sums.

    ``prefixes`` is ``(rows, cols + 1, K)`` with K ≤ 4 for the box starting at
    ``(r0, c0)`` (see :func:`row_prefix`); the box must contain every disk
    (clipped to the image ``h × w``). Returns ``(N, K)``.
    """
    n = band.shape[0]
    kk = prefixes.shape[2]
    r = (hw.shape[0] - 1) // 2
    rows = prefixes.shape[0]
    cols = prefixes.shape[1] - 1
    out = np.zeros((n, kk))
    for k in range(n):
        i, j = band[k, 0], band[k, 1]
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        a3 = 0.0
        d_lo = max(-r, -i, r0 - i)
        d_hi = min(r, h - 1 - i, rows - 1 + r0 - i)
        for d in range(d_lo, d_hi + 1):
            pi = i + d - r0
            half = hw[d + r]
            lo = min(max(max(j - half, 0) - c0, 0), cols)
            hi = min(max(min(j + half, w - 1) - c0 + 1, 0), cols)
            a0 += prefixes[pi, hi, 0] - prefixes[pi, lo, 0]
            if kk > 1:
                a1 += prefixes[pi, hi, 1] - prefixes[pi, lo, 1]
            if kk > 2:
                a2 += prefixes[pi, hi, 2] - prefixes[pi, lo, 2]
                a3 += prefixes[pi, hi, 3] - prefixes[pi, lo, 3]
        out[k, 0] = a0
        if kk > 1:
            out[k, 1] = a1
        if kk > 2:
            out[k, 2] = a2
            out[k, 3] = a3
    return out


@njit(cache=True)
def stack_local_fields(phi, image, eps, r0, r1, c0, c1, with_delta):
    """The four fields whose disk sums give LCV's local statistics, on the box ``r0:r1, c0:c1``.

    ``H = [φ > 0]``, ``H·I``, ``δ_ε(φ)`` and ``δ_ε(φ)·I``, as row prefix sums
    ``(rows, cols + 1, 4)``, with the compactly supported regularised Dirac
    ``δ_ε(φ) = ½ (1 + cos(πφ/ε))`` for ``|φ| < ε`` (0 beyond), scaled to 1 at φ = 0.
    """
    out = np.zeros((r1 - r0, c1 - c0 + 1, 4 if with_delta else 2))
    for i in range(r0, r1):
        sh = 0.0
        shi = 0.0
        sd = 0.0
        sdi = 0.0
        for j in range(c0, c1):
            p = phi[i, j]
            v = image[i, j]
            if p > 0:
                sh += 1.0
                shi += v
            k = j - c0 + 1
            out[i - r0, k, 0] = sh
            out[i - r0, k, 1] = shi
            if with_delta:
                if abs(p) < eps:
                    dlt = 0.5 * (1.0 + np.cos(np.pi * p / eps))
                    sd += dlt
                    sdi += dlt * v
                out[i - r0, k, 2] = sd
                out[i - r0, k, 3] = sdi
    return out


@njit(cache=True)
def apply_update(phi, band, speed, dt, limit):
    """``φ += dt · speed`` on the band, clamped to ``±limit``; returns the number of sign changes."""
    flips = 0
    for k in range(band.shape[0]):
        i, j = band[k, 0], band[k, 1]
        old = phi[i, j]
        new = old + dt * speed[k]
        new = min(max(new, -limit), limit)
        if (old > 0) != (new > 0):
            flips += 1
        phi[i, j] = new
    return flips


@njit(cache=True)
def band_bounds(phi, limit, r0, r1, c0, c1):
    """Bounding box ``(r0, r1, c0, c1)`` of the pixels of the window with ``|phi| <= limit``
    (``(0, 0, 0, 0)`` when there is none)."""
    h, w = phi.shape
    lo_r, hi_r, lo_c, hi_c = h, -1, w, -1
    for i in range(max(r0, 0), min(r1, h)):
        for j in range(max(c0, 0), min(c1, w)):
            if abs(phi[i, j]) <= limit:
                if i < lo_r:
                    lo_r = i
                if i > hi_r:
                    hi_r = i
                if j < lo_c:
                    lo_c = j
                if j > hi_c:
                    hi_c = j
    if hi_r < 0:
        return 0, 0, 0, 0
    return lo_r, hi_r + 1, lo_c, hi_c + 1


@njit(cache=True)
def count_changed(phi, snapshot, r0, r1, c0, c1):
    """Pixels of the window whose side (``phi > 0``) differs from the boolean ``snapshot``."""
    n = 0
    for i in range(r0, r1):
        for j in range(c0, c1):
            if (phi[i, j] > 0) != snapshot[i, j]:
                n += 1
    return n


@njit(cache=True)
def local_region_force(phi, image, point_image, band, hw, r0, r1, c0, c1, static_prefix, count, total,
                       scale, eps, integral):
    """LCV's region force (Eq. 2–5) at every band point, in one pass.

    The disk sums of ``H = [φ > 0]`` and ``H·I`` (and, with ``integral``, of
    ``δ_ε(φ)`` and ``δ_ε(φ)·I``) come from row prefix sums over the window
    ``r0:r1, c0:c1`` built here; the pixel count and intensity sum of each ball
    come from ``count``/``total``, filled from ``static_prefix`` the first time
    a pixel needs them (NaN marks "not yet"). Returns ``(force, c_in, c_out)``:
    ``force = clip(−(c_in − c_out)(c_in + c_out − 2v) / scale, −1, 1)`` with
    ``v`` the δ-weighted mean intensity in the ball (``integral``) or
    ``point_image`` at the point; 0 where a side of the ball is empty.
    """
    h, w = phi.shape
    dyn = stack_local_fields(phi, image, eps, r0, r1, c0, c1, integral)
    sums = disk_sums(dyn, band, hw, r0, c0, h, w)
    n = band.shape[0]
    r = (hw.shape[0] - 1) // 2
    force = np.zeros(n)
    c_in = np.full(n, np.nan)
    c_out = np.full(n, np.nan)
    for k in range(n):
        i, j = band[k, 0], band[k, 1]
        if np.isnan(count[i, j]):
            a = 0.0
            b = 0.0
            for d in range(max(-r, -i), min(r, h - 1 - i) + 1):
                lo = max(j - hw[d + r], 0)
                hi = min(j + hw[d + r], w - 1) + 1
                a += static_prefix[i + d, hi, 0] - static_prefix[i + d, lo, 0]
                b += static_prefix[i + d, hi, 1] - static_prefix[i + d, lo, 1]
            count[i, j] = a
            total[i, j] = b
        n_in, s_in = sums[k, 0], sums[k, 1]
        n_out = count[i, j] - n_in
        if n_in <= 0 or n_out <= 0:
            continue
        u = s_in / n_in
        v_out = (total[i, j] - s_in) / n_out
        c_in[k] = u
        c_out[k] = v_out
        if integral:
            if sums[k, 2] <= 0:
                continue
            value = sums[k, 3] / sums[k, 2]
        else:
            value = point_image[i, j]
        f = -(u - v_out) * (u + v_out - 2.0 * value) / scale
        force[k] = min(max(f, -1.0), 1.0)
    return force, c_in, c_out


@njit(cache=True)
def add_geodesic_where_flat(force, c_in, c_out, kappa1, phi, band, g, gx, gy, weight):
    """GLCV's speed (Eq. 7): the region force plus, where ``|c_in − c_out| < κ1`` (t(x) = 1,
    Eq. 6), the geodesic bracket with the balloon weight ``weight`` (an image)."""
    n = band.shape[0]
    flat = np.zeros(n, np.bool_)
    m = 0
    for k in range(n):
        d = c_in[k] - c_out[k]
        if not np.isnan(d) and abs(d) < kappa1:
            flat[k] = True
            m += 1
    if m == 0:
        return force
    sub = np.empty((m, 2), np.int32)
    alpha = np.empty(m)
    q = 0
    for k in range(n):
        if flat[k]:
            sub[q, 0], sub[q, 1] = band[k, 0], band[k, 1]
            alpha[q] = weight[band[k, 0], band[k, 1]]
            q += 1
    geo = geodesic_terms(phi, sub, g, gx, gy, alpha)
    out = force.copy()
    q = 0
    for k in range(n):
        if flat[k]:
            out[k] += geo[q]
            q += 1
    return out


@njit(cache=True)
def time_step(force, cfl, mu):
    """``(peak, Δt)``: the largest |speed| and the step ``cfl / max(peak, 1)``, at most
    ``0.25 / μ`` (the explicit limit of a curvature term of weight μ). Raises on a non-finite speed."""
    peak = 0.0
    for k in range(force.shape[0]):
        a = abs(force[k])
        if a > peak:
            peak = a
    if not np.isfinite(peak):
        raise FloatingPointError("level-set speed is not finite")
    dt = cfl / max(peak, 1.0)
    if mu != 0.0:
        dt = min(dt, 0.25 / mu)
    return peak, dt


@njit(cache=True)
def evolve_region(phi, image, point_image, hw, radius_px, static_prefix, count, total, scale, eps, integral,
                  geodesic, kappa1, g, gx, gy, weight, mu, max_iterations, cfl, band_w, update_band,
                  window, fraction):
    """The whole narrow-band evolution of LCV (Eq. 5) or GLCV (Eq. 7) in one compiled loop.

    The same steps as :func:`hifumotion.segmentation.levelset.evolve` with the
    speed of :func:`local_region_force` (+ :func:`add_geodesic_where_flat` when
    ``geodesic``) and the curvature weight ``mu``; without a Python call per
    iteration. Returns ``(iterations, converged)``; ``phi`` is updated in place.
    """
    h, w = phi.shape
    margin = int(band_w) + 2
    r = int(np.ceil(radius_px))
    b = band_bounds(phi, band_w, 0, h, 0, w)
    box = (max(b[0] - margin, 0), min(b[1] + margin, h), max(b[2] - margin, 0), min(b[3] + margin, w))
    snapshot = np.zeros((h, w), np.bool_)
    for i in range(h):
        for j in range(w):
            snapshot[i, j] = phi[i, j] > 0
    snap_box = box
    stamp = np.zeros((h, w), np.int64)
    it = 0
    converged = False
    while it < max_iterations:
        it += 1
        band = band_points(phi, update_band, box[0], box[1], box[2], box[3])
        if band.shape[0] == 0:
            break
        r0, r1 = max(box[0] - r, 0), min(box[1] + r, h)
        c0, c1 = max(box[2] - r, 0), min(box[3] + r, w)
        force, c_in, c_out = local_region_force(phi, image, point_image, band, hw, r0, r1, c0, c1, static_prefix,
                                                count, total, scale, eps, integral)
        if geodesic:
            force = add_geodesic_where_flat(force, c_in, c_out, kappa1, phi, band, g, gx, gy, weight)
        if mu != 0.0:
            kappa = curvature(phi, band)
            for k in range(force.shape[0]):
                force[k] += mu * kappa[k]
        peak, dt = time_step(force, cfl, mu)
        if peak < 1e-9:
            converged = True
            break
        apply_update(phi, band, force, dt, band_w + 1.0)
        g0, g1 = max(box[0] - 1, 0), min(box[1] + 1, h)
        g2, g3 = max(box[2] - 1, 0), min(box[3] + 1, w)
        segments = interface_segments_near(phi, band, stamp, it)
        redistance_box(phi, segments, band_w, g0, g1, g2, g3)
        b = band_bounds(phi, band_w, g0, g1, g2, g3)
        if b[1] == 0:
            break
        box = (max(b[0] - margin, 0), min(b[1] + margin, h), max(b[2] - margin, 0), min(b[3] + margin, w))
        if it % window == 0:
            u0, u1 = min(box[0], snap_box[0]), max(box[1], snap_box[1])
            u2, u3 = min(box[2], snap_box[2]), max(box[3], snap_box[3])
            changed = count_changed(phi, snapshot, u0, u1, u2, u3)
            length = max(band.shape[0] / (2 * update_band + 1), 1.0)
            if changed <= fraction * length * window:
                converged = True
                break
            for i in range(u0, u1):
                for j in range(u2, u3):
                    snapshot[i, j] = phi[i, j] > 0
            snap_box = box
    return it, converged


# --------------------------------------------------------------------------- the edge function


@njit(cache=True, inline="always")
def gradient_at(a, i, j):
    """``(∂a/∂row, ∂a/∂col)`` as ``np.gradient``: central differences, one-sided at the borders."""
    h, w = a.shape
    if h == 1:
        gy = 0.0
    elif i == 0:
        gy = a[1, j] - a[0, j]
    elif i == h - 1:
        gy = a[h - 1, j] - a[h - 2, j]
    else:
        gy = 0.5 * (a[i + 1, j] - a[i - 1, j])
    if w == 1:
        gx = 0.0
    elif j == 0:
        gx = a[i, 1] - a[i, 0]
    elif j == w - 1:
        gx = a[i, w - 1] - a[i, w - 2]
    else:
        gx = 0.5 * (a[i, j + 1] - a[i, j - 1])
    return gy, gx


@njit(cache=True)
def gradient_magnitude2(a):
    """``|∇a|²`` with ``np.gradient``'s differences."""
    h, w = a.shape
    out = np.empty((h, w))
    for i in range(h):
        for j in range(w):
            gy, gx = gradient_at(a, i, j)
            out[i, j] = gx * gx + gy * gy
    return out


@njit(cache=True)
def edge_function(mag2, lam2):
    """``g = 1 / (1 + |∇I_σ|² / λ²)`` and its gradient ``(g, ∂g/∂x, ∂g/∂y)`` (``np.gradient``'s differences)."""
    h, w = mag2.shape
    g = np.empty((h, w))
    for i in range(h):
        for j in range(w):
            g[i, j] = 1.0 / (1.0 + mag2[i, j] / lam2)
    gx = np.empty((h, w))
    gy = np.empty((h, w))
    for i in range(h):
        for j in range(w):
            gy[i, j], gx[i, j] = gradient_at(g, i, j)
    return g, gx, gy
