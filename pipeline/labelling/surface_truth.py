"""The simulated boxes' visible faces as surfaces (the ground truth of surface detection), and the
scores of detected surfaces against them (paper Sec. 4.3, Fig. 4c). Frames and units as in
``pipeline.grasping.surfaces``."""

from __future__ import annotations

import numpy as np

from pipeline.camera.geometry import Intrinsics
from pipeline.grasping.surfaces import (
    FACES,
    RegionFinder,
    check_images,
    instance_pixels,
    region_surface,
)
from pipeline.grasping.types import Surface


def true_visible_faces(
    depth_m: np.ndarray,
    mask: np.ndarray,
    intrinsics: Intrinsics,
    boxes,
    min_visible_px: int,
    tolerance_m: float = 0.002,
) -> list[Surface]:
    """The faces of the simulated boxes that the camera sees, as Surfaces.

    A pixel of instance k belongs to face f of ``boxes[k-1]`` if f's outward normal faces the
    camera, the pixel's back-projected point is within ``tolerance_m`` of f's plane and inside
    f's rectangle grown by ``tolerance_m``; a pixel that qualifies for two faces (next to an
    edge) goes to the nearer plane. The face's visible region is its largest connected region
    (4-connected) of such pixels, and the face counts if that region has at least
    ``min_visible_px`` pixels. The Surface is computed from the region as in
    ``detect_surfaces`` but on the exact face plane, so its centre is the centre of the visible
    part of the true face.

    Args:
        depth_m, mask, intrinsics: as for ``detect_surfaces``; mask value k is ``boxes[k-1]``.
        boxes: sequence of objects with ``size`` (3,) edge lengths in metres and ``T_cam_box``
            (4, 4) pose in the camera frame, e.g. ``pipeline.dataset.scenes.Box``.
        min_visible_px: fewest pixels in the visible region.
        tolerance_m: distance to the face plane and margin around the face rectangle.

    Pass noise-free depth (``sensor=ideal``): with sensor noise the tolerance drops pixels
    and the regions get holes.

    Returns:
        Surfaces ordered by instance, then by decreasing pixel count. ``extra``: ``face`` ("+x",
        "-x", ... in the box frame), ``face_pixels`` (all pixels of the face, every region),
        ``full_face_center_cam`` (3,) and ``full_face_size`` (a, b): edge lengths of the whole
        face along its two box axes in x, y, z order.
    """
    check_images(depth_m, mask, intrinsics)
    surfaces: list[Surface] = []
    for instance, us, vs, xn, yn, points in instance_pixels(depth_m, mask, intrinsics):
        if instance > len(boxes):
            raise ValueError(
                f"mask has instance {instance} but only {len(boxes)} boxes were "
                "given; pass the scene's boxes in instance order"
            )
        if len(us) < min_visible_px:
            continue
        box = boxes[instance - 1]
        size = np.asarray(box.size, dtype=np.float64)
        T = np.asarray(box.T_cam_box, dtype=np.float64)
        R, t = T[:3, :3], T[:3, 3]
        half = size / 2.0
        nearest, on_face = _nearest_faces(points, R, t, half, tolerance_m)
        regions = RegionFinder(us, vs, 4)
        found = []
        for f, (name, axis, sign) in enumerate(FACES):
            idx = np.flatnonzero(on_face & (nearest == f))
            face_pixels = len(idx)
            if face_pixels < min_visible_px:
                continue
            keep, _ = regions.largest(us[idx], vs[idx])
            if keep is not None:
                idx = idx[keep]
                if len(idx) < min_visible_px:
                    continue
            normal = sign * R[:, axis]
            face_centre = t + sign * half[axis] * R[:, axis]
            a, b = [k for k in range(3) if k != axis]
            extra = {
                "face": name,
                "face_pixels": face_pixels,
                "full_face_center_cam": face_centre,
                "full_face_size": (float(size[a]), float(size[b])),
            }
            pixels, offset = (us[idx], vs[idx], xn[idx], yn[idx]), float(normal @ face_centre)
            surface = region_surface(
                instance, *pixels, normal, offset, R[:, a], R[:, b], intrinsics, extra
            )
            if surface is not None:
                found.append(surface)
        found.sort(key=lambda s: -s.num_points)
        surfaces.extend(found)
    return surfaces


def _nearest_faces(
    points: np.ndarray, R: np.ndarray, t: np.ndarray, half: np.ndarray, tolerance_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """For each camera-frame point (N, 3) of one box (rotation ``R``, centre ``t``, half edge
    lengths ``half``, camera frame, metres): the index into ``FACES`` of the nearest face that
    faces the camera and holds the point within ``tolerance_m``, and whether there is one."""
    local = (points - t) @ R  # (N, 3) box frame
    dist = np.full((len(points), len(FACES)), np.inf)
    for f, (_, axis, sign) in enumerate(FACES):
        normal = sign * R[:, axis]
        face_centre = t + sign * half[axis] * R[:, axis]
        if normal @ face_centre >= 0:  # faces away from the camera (at the origin)
            continue
        d = np.abs(sign * local[:, axis] - half[axis])
        others = [a for a in range(3) if a != axis]
        inside = np.all(np.abs(local[:, others]) <= half[others] + tolerance_m, axis=1)
        ok = inside & (d < tolerance_m)
        dist[ok, f] = d[ok]
    nearest = np.argmin(dist, axis=1)
    return nearest, np.isfinite(dist[np.arange(len(points)), nearest])


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))


def _stats(values: list[float], prefix: str) -> dict:
    """Median and 90th percentile of ``values`` (None when empty), keys ``<prefix>_median/p90``."""
    if not values:
        return {f"{prefix}_median": None, f"{prefix}_p90": None}
    arr = np.asarray(values, dtype=np.float64)
    return {
        f"{prefix}_median": float(np.median(arr)),
        f"{prefix}_p90": float(np.percentile(arr, 90)),
    }


def _summary(pairs: list[dict], found: int, missed: int, spurious: int) -> dict:
    out = {
        "found": found,
        "missed": missed,
        "spurious": spurious,
        "recall": found / (found + missed) if found + missed else None,
        "precision": found / (found + spurious) if found + spurious else None,
    }
    out.update(_stats([p["center_err_px"] for p in pairs], "center_err_px"))
    out.update(_stats([p["center_err_mm"] for p in pairs], "center_err_mm"))
    out.update(_stats([p["normal_err_deg"] for p in pairs], "normal_err_deg"))
    return out


def match_surfaces(
    detected: list[Surface],
    truth: list[Surface],
    max_center_dist_m: float = 0.02,
    max_normal_deg: float = 20.0,
) -> dict:
    """Greedy one-to-one matching of detected to true surfaces of the same instance.

    Candidate pairs have the same instance, centres within ``max_center_dist_m`` and normals
    within ``max_normal_deg``; they are taken in order of increasing centre distance, each
    surface at most once.

    Returns:
        A JSON-serialisable dict: ``found``, ``missed`` (true surfaces left unmatched),
        ``spurious`` (detected ones left unmatched), ``recall``, ``precision``, median and p90 of
        ``center_err_px`` (image distance of ``center_px``), ``center_err_mm`` (3-D) and
        ``normal_err_deg``, plus ``pairs`` (one record per match: instance, detected / true
        index, the three errors, true and detected pixel counts, the true face name),
        ``missed_truth`` and ``spurious_detected`` (instance, index, num_points[, face]).
        Statistics of an empty set are None.
    """
    candidates = []
    for i, d in enumerate(detected):
        for j, t in enumerate(truth):
            if d.instance != t.instance:
                continue
            dist = float(np.linalg.norm(d.center_cam - t.center_cam))
            angle = _angle_deg(d.normal_cam, t.normal_cam)
            if dist <= max_center_dist_m and angle <= max_normal_deg:
                candidates.append((dist, i, j, angle))
    candidates.sort()
    used_d, used_t, pairs = set(), set(), []
    for dist, i, j, angle in candidates:
        if i in used_d or j in used_t:
            continue
        used_d.add(i)
        used_t.add(j)
        d, t = detected[i], truth[j]
        pairs.append(
            {
                "instance": int(t.instance),
                "detected": i,
                "truth": j,
                "face": t.extra.get("face"),
                "center_err_px": float(
                    np.linalg.norm(np.asarray(d.center_px, float) - np.asarray(t.center_px, float))
                ),
                "center_err_mm": dist * 1000.0,
                "normal_err_deg": angle,
                "truth_points": int(t.num_points),
                "detected_points": int(d.num_points),
            }
        )
    missed = [
        {
            "instance": int(t.instance),
            "truth": j,
            "num_points": int(t.num_points),
            "face": t.extra.get("face"),
        }
        for j, t in enumerate(truth)
        if j not in used_t
    ]
    spurious = [
        {"instance": int(d.instance), "detected": i, "num_points": int(d.num_points)}
        for i, d in enumerate(detected)
        if i not in used_d
    ]
    out = _summary(pairs, len(pairs), len(missed), len(spurious))
    out.update({"pairs": pairs, "missed_truth": missed, "spurious_detected": spurious})
    return out


def aggregate(matches: list[dict]) -> dict:
    """Totals and error statistics over many ``match_surfaces`` results (a whole dataset).

    Returns the same summary keys as ``match_surfaces`` (without the per-record lists) plus
    ``images``; plain ints / floats / None, JSON-serialisable.
    """
    pairs = [p for m in matches for p in m["pairs"]]
    out = {"images": len(matches)}
    out.update(
        _summary(
            pairs,
            sum(m["found"] for m in matches),
            sum(m["missed"] for m in matches),
            sum(m["spurious"] for m in matches),
        )
    )
    return out
