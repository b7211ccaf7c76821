"""Pinhole camera with radial distortion and camera poses for the simulated kite photos.

Conventions
-----------
World: site CRS, x east, y north, z up (m). Camera frame (OpenCV/COLMAP): x to the image
right, y to the image bottom, z along the optical axis. A pose is a rotation ``R``
(world → camera) and a centre ``C`` (world), so ``X_cam = R (X_world − C)``.

Intrinsics follow COLMAP's ``RADIAL`` model: one focal length ``f`` (square pixels), a
principal point ``(cx, cy)`` and two radial coefficients applied to normalised coordinates,
``x_d = x (1 + k1 r² + k2 r⁴)``. Pixel centres are at integer coordinates; the image spans
``[-0.5, width − 0.5]``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from kitegully import InputError


@dataclass(frozen=True)
class Camera:
    """Intrinsics of a frame camera.

    Attributes
    ----------
    width, height : int
        Image size (px).
    f : float
        Focal length (px).
    cx, cy : float
        Principal point (px, pixel centres at integers).
    k1, k2 : float
        Radial distortion coefficients (normalised coordinates).
    sensor_width_mm, sensor_height_mm, focal_length_mm : float
        Physical values written to EXIF.
    make, model : str
        Camera make and model for EXIF.
    """

    width: int
    height: int
    f: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    sensor_width_mm: float = 23.4
    sensor_height_mm: float = 15.6
    focal_length_mm: float = 18.0
    make: str = "SONY"
    model: str = "NEX-5N"

    @property
    def pixel_pitch_mm(self) -> float:
        """Pixel pitch on the sensor (mm): sensor width / image width."""
        return self.sensor_width_mm / self.width

    @property
    def K(self) -> np.ndarray:
        """3×3 calibration matrix."""
        return np.array([[self.f, 0.0, self.cx], [0.0, self.f, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        """OpenCV distortion vector ``(k1, k2, p1, p2)``."""
        return np.array([self.k1, self.k2, 0.0, 0.0])

    def gsd(self, distance_m: float | np.ndarray) -> float | np.ndarray:
        """Ground sampling distance (m) at ``distance_m`` along the axis: ``H·p/f``."""
        return np.asarray(distance_m) / self.f

    def footprint(self, distance_m: float) -> tuple[float, float]:
        """Nadir footprint (across image width, across image height) in m: ``H·S/f``."""
        return distance_m * self.width / self.f, distance_m * self.height / self.f

    def distort(self, xn: np.ndarray, yn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Apply radial distortion to normalised coordinates."""
        r2 = xn * xn + yn * yn
        s = 1.0 + self.k1 * r2 + self.k2 * r2 * r2
        return xn * s, yn * s

    def undistort(self, xd: np.ndarray, yd: np.ndarray, iterations: int = 20) -> tuple[np.ndarray, np.ndarray]:
        """Invert :meth:`distort` by fixed-point iteration (converges for |k·r²| ≪ 1).

        Parameters
        ----------
        xd, yd : ndarray
            Distorted normalised coordinates.
        iterations : int
            Number of fixed-point iterations.

        Returns
        -------
        xn, yn : ndarray
            Undistorted normalised coordinates.
        """
        xn, yn = np.array(xd, dtype=float), np.array(yd, dtype=float)
        for _ in range(iterations):
            r2 = xn * xn + yn * yn
            s = 1.0 + self.k1 * r2 + self.k2 * r2 * r2
            xn, yn = xd / s, yd / s
        return xn, yn

    def project_camera(self, Xc: np.ndarray) -> np.ndarray:
        """Project points in the camera frame (N×3) to pixels (N×2); NaN behind the camera."""
        Xc = np.atleast_2d(np.asarray(Xc, dtype=float))
        z = Xc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xn, yn = Xc[:, 0] / z, Xc[:, 1] / z
        xd, yd = self.distort(xn, yn)
        uv = np.column_stack([self.f * xd + self.cx, self.f * yd + self.cy])
        uv[z <= 0] = np.nan
        return uv

    def project(self, X: np.ndarray, pose: "Pose") -> np.ndarray:
        """Project world points (N×3) through ``pose`` to pixels (N×2)."""
        return self.project_camera(pose.world_to_camera(X))

    def rays_camera(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Unit viewing directions (…×3, camera frame) of pixel positions ``(u, v)``."""
        xn, yn = self.undistort((np.asarray(u) - self.cx) / self.f, (np.asarray(v) - self.cy) / self.f)
        d = np.stack([xn, yn, np.ones_like(xn)], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def in_image(self, uv: np.ndarray, margin_px: float = 0.0) -> np.ndarray:
        """Boolean mask of pixel positions inside the image, ``margin_px`` from its border."""
        u, v = uv[..., 0], uv[..., 1]
        lo = -0.5 + margin_px
        return (u >= lo) & (v >= lo) & (u <= self.width - 0.5 - margin_px) & (v <= self.height - 0.5 - margin_px)

    def to_dict(self) -> dict[str, Any]:
        """The fields plus the COLMAP ``RADIAL`` model and parameters, pixel pitch (mm) and conventions."""
        d = asdict(self)
        d.update(
            colmap_model="RADIAL",
            colmap_params=[self.f, self.cx, self.cy, self.k1, self.k2],
            pixel_pitch_mm=self.pixel_pitch_mm,
            conventions="pixel centres at integer coordinates; x_d = x(1 + k1 r^2 + k2 r^4) on normalised coordinates",
        )
        return d

    def write_json(self, path: str | Path) -> None:
        """Write :meth:`to_dict` as indented JSON, creating the parent folder."""
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n", encoding="utf-8")

    @classmethod
    def read_json(cls, path: str | Path) -> "Camera":
        """Read a camera written by :meth:`write_json` (extra keys ignored); InputError if unreadable."""
        try:
            d = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise InputError(f"{path}: cannot read camera JSON ({exc})") from None
        names = cls.__dataclass_fields__.keys()
        return cls(**{k: d[k] for k in names if k in d})


def camera_from_config(cam: Mapping[str, Any]) -> Camera:
    """Build the camera from the ``flight.camera`` config section.

    The focal length in pixels is ``focal_length_mm · image_width_px / sensor_width_mm``;
    the principal point is the image centre plus ``principal_point_offset_px``.
    """
    w, h = int(cam["image_width_px"]), int(cam["image_height_px"])
    f = cam["focal_length_mm"] * w / cam["sensor_width_mm"]
    dx, dy = cam["principal_point_offset_px"]
    return Camera(
        width=w,
        height=h,
        f=float(f),
        cx=(w - 1) / 2.0 + float(dx),
        cy=(h - 1) / 2.0 + float(dy),
        k1=float(cam["k1"]),
        k2=float(cam["k2"]),
        sensor_width_mm=float(cam["sensor_width_mm"]),
        sensor_height_mm=float(cam["sensor_height_mm"]),
        focal_length_mm=float(cam["focal_length_mm"]),
        make=str(cam["make"]),
        model=str(cam["model"]),
    )


@dataclass(frozen=True)
class Pose:
    """Camera pose: rotation world → camera ``R`` (3×3) and centre ``C`` (3,) in world."""

    R: np.ndarray
    C: np.ndarray

    def world_to_camera(self, X: np.ndarray) -> np.ndarray:
        """World points (N×3) in the camera frame: ``R (X − C)``."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        return (X - self.C) @ self.R.T

    @property
    def t(self) -> np.ndarray:
        """Translation of ``X_cam = R X + t``."""
        return -self.R @ self.C

    def quaternion(self) -> np.ndarray:
        """``(qw, qx, qy, qz)`` of ``R`` (world → camera, COLMAP convention), qw ≥ 0."""
        return rotation_to_quaternion(self.R)


def rotation_x(a: float) -> np.ndarray:
    """Rotation matrix about the x axis.

    Parameters
    ----------
    a : float
        Angle (radians), right-handed.

    Returns
    -------
    ndarray (3, 3)
    """
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(a: float) -> np.ndarray:
    """Rotation matrix about the y axis.

    Parameters
    ----------
    a : float
        Angle (radians), right-handed.

    Returns
    -------
    ndarray (3, 3)
    """
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def nadir_rotation(heading_deg: float, omega_deg: float = 0.0, phi_deg: float = 0.0) -> np.ndarray:
    """World → camera rotation of a downward-looking camera.

    Parameters
    ----------
    heading_deg
        Azimuth (clockwise from north, degrees) of the image "up" direction (−y_cam).
    omega_deg, phi_deg
        Tilts about the camera x axis and y axis (degrees), applied after the nadir
        rotation: ``R = Rx(ω) Ry(φ) R_nadir``. Zero gives a perfectly vertical view.
    """
    k = np.radians(heading_deg)
    up = np.array([np.sin(k), np.cos(k), 0.0])
    right = np.array([np.cos(k), -np.sin(k), 0.0])
    r_nadir = np.vstack([right, -up, [0.0, 0.0, -1.0]])
    return rotation_x(np.radians(omega_deg)) @ rotation_y(np.radians(phi_deg)) @ r_nadir


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix (Shepperd's method), w ≥ 0."""
    m = np.asarray(R, dtype=float)
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
