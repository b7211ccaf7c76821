"""The paper's stereo rig: two Nikon D2H cameras with their own inner orientation.

Moritani et al. (2010) Table 1 gives, per camera, the corrected focal length (mm), the
principal-point offset (mm) and the radial distortion ``Δr = K1·r³ + K2·r⁵`` (r in mm on
the sensor). :class:`kitegully.twin.camera.Camera` uses normalised coordinates,
``x_d = x(1 + k1 r_n² + k2 r_n⁴)`` with ``r_n = r/f``, so ``k1 = K1·f²`` and
``k2 = K2·f⁴`` (f in mm); :func:`radial_mm_to_normalised` and its inverse convert.

Precision: ``δz = (H/f)(H/B)·δ_CCD = L·δ_CCD/f`` with ``L = H²/B`` (Eqs 1 and 4). The
formula lives in :func:`kitegully.tether.planning.stereo_precision_m` (the flight
planner budgets with it); :func:`delta_z_m` only adapts a twin camera to it and scales it
by the matching precision in pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kitegully import InputError
from kitegully.tether.planning import PlanningCamera
from kitegully.tether.planning import stereo_precision_m
from kitegully.twin.camera import Camera, Pose

#: Image size of the Nikon D2H (px).
D2H_SIZE_PX = (2464, 1632)
#: Pixel pitch (mm). [I] The paper prints 0.094 mm, which would make a 232 mm sensor;
#: 0.0094 mm reproduces its "δz of 0.19" (METHODS 4.6).
D2H_PIXEL_MM = 0.0094
#: Nominal focal length of the lenses (mm).
D2H_NOMINAL_F_MM = 50.0

#: Paper Table 1 [P]: corrected f (mm), principal point (mm; [I] "longitudinal" = along the
#: long side = image x, "horizontal" = image y), K1 (mm⁻²), K2 (mm⁻⁴).
PAPER_TABLE1 = {
    "left": {"f_mm": 51.4, "x0_mm": -2.2e-3, "y0_mm": -7.7e-3, "K1": 7.6e-6, "K2": 2.0e-8},
    "right": {"f_mm": 51.5, "x0_mm": 3.8e-3, "y0_mm": 7.9e-3, "K1": 1.3e-6, "K2": 2.2e-8},
}


def radial_mm_to_normalised(K1: float, K2: float, f_mm: float) -> tuple[float, float]:
    """Convert ``Δr = K1 r³ + K2 r⁵`` (r in mm) to normalised ``(k1, k2)``: ``k1 = K1 f²``, ``k2 = K2 f⁴``.

    Parameters
    ----------
    K1, K2 : float
        Radial distortion coefficients (mm⁻², mm⁻⁴).
    f_mm : float
        Focal length (mm).

    Returns
    -------
    k1 : float
        Normalised coefficient of r_n².
    k2 : float
        Normalised coefficient of r_n⁴.
    """
    return K1 * f_mm**2, K2 * f_mm**4


def radial_normalised_to_mm(k1: float, k2: float, f_mm: float) -> tuple[float, float]:
    """Inverse of :func:`radial_mm_to_normalised`: ``K1 = k1/f²``, ``K2 = k2/f⁴`` (mm⁻², mm⁻⁴).

    Parameters
    ----------
    k1, k2 : float
        Normalised radial distortion coefficients.
    f_mm : float
        Focal length (mm).

    Returns
    -------
    K1 : float
        Coefficient of r³ (mm⁻²).
    K2 : float
        Coefficient of r⁵ (mm⁻⁴).
    """
    return k1 / f_mm**2, k2 / f_mm**4


def camera_from_table(row: dict, size_px: tuple[int, int] = D2H_SIZE_PX, pixel_mm: float = D2H_PIXEL_MM) -> Camera:
    """A twin :class:`Camera` from one Table-1 style row (``f_mm, x0_mm, y0_mm, K1, K2``).

    Parameters
    ----------
    row : dict
        Inner orientation in the paper's units (mm, mm⁻², mm⁻⁴).
    size_px : (int, int)
        Image width and height (px).
    pixel_mm : float
        Pixel pitch (mm).

    Returns
    -------
    Camera
        ``f = f_mm/pitch`` px, principal point at the image centre plus the offset.
    """
    w, h = size_px
    f_mm = float(row["f_mm"])
    if not (f_mm > 0 and pixel_mm > 0):
        raise InputError(f"camera row {row}: focal length and pixel pitch must be positive")
    k1, k2 = radial_mm_to_normalised(float(row["K1"]), float(row["K2"]), f_mm)
    return Camera(
        width=w, height=h, f=f_mm / pixel_mm,
        cx=(w - 1) / 2.0 + float(row["x0_mm"]) / pixel_mm,
        cy=(h - 1) / 2.0 + float(row["y0_mm"]) / pixel_mm,
        k1=k1, k2=k2,
        sensor_width_mm=w * pixel_mm, sensor_height_mm=h * pixel_mm,
        focal_length_mm=D2H_NOMINAL_F_MM, make="NIKON", model="D2H",
    )


def camera_to_table(camera: Camera) -> dict:
    """Inner orientation of a twin camera in the paper's Table-1 units (inverse of :func:`camera_from_table`)."""
    p = camera.pixel_pitch_mm
    f_mm = camera.f * p
    K1, K2 = radial_normalised_to_mm(camera.k1, camera.k2, f_mm)
    return {
        "f_mm": f_mm,
        "x0_mm": (camera.cx - (camera.width - 1) / 2.0) * p,
        "y0_mm": (camera.cy - (camera.height - 1) / 2.0) * p,
        "K1": K1,
        "K2": K2,
    }


def paper_cameras() -> dict[str, Camera]:
    """The paper's left and right cameras (Table 1 [P], pitch 0.0094 mm [I])."""
    return {side: camera_from_table(row) for side, row in PAPER_TABLE1.items()}


def nadir_pose(centre: np.ndarray, omega_deg: float = 0.0, phi_deg: float = 0.0, kappa_deg: float = 0.0) -> Pose:
    """Pose of a camera looking straight down (image x = world x, image y = −world y), tilted by small angles.

    The rotation is ``R = R_κ R_φ R_ω R_nadir`` (world → camera), angles about the camera's x, y, z axes.

    Parameters
    ----------
    centre : ndarray (3,)
        Projection centre (world, m).
    omega_deg, phi_deg, kappa_deg : float
        Small rotations about the camera's x, y and z axes (degrees).

    Returns
    -------
    Pose
    """
    import cv2

    Rn = np.diag([1.0, -1.0, -1.0])
    rv = np.radians([omega_deg, phi_deg, kappa_deg])
    Rt = cv2.Rodrigues(np.asarray(rv, float))[0]
    return Pose(R=Rt @ Rn, C=np.asarray(centre, float))


@dataclass(frozen=True)
class StereoRig:
    """Two cameras and their poses over a scene; the base is along world x.

    Attributes
    ----------
    left, right : Camera
        Inner orientation of each camera.
    pose_left, pose_right : Pose
        Exterior orientation (world → camera), world z up (m).
    """

    left: Camera
    right: Camera
    pose_left: Pose
    pose_right: Pose

    @property
    def base_m(self) -> float:
        """Base length B (m): distance between the projection centres."""
        return float(np.linalg.norm(self.pose_right.C - self.pose_left.C))

    def height_m(self, z_object: float = 0.0) -> float:
        """Mean camera height H above the object plane ``z_object`` (m)."""
        return float((self.pose_left.C[2] + self.pose_right.C[2]) / 2.0 - z_object)


def look_at_pose(centre: np.ndarray, target: np.ndarray, omega_deg: float = 0.0, phi_deg: float = 0.0, kappa_deg: float = 0.0) -> Pose:
    """Pose whose optical axis passes through ``target`` (image x along world x), then tilted by small angles.

    Parameters
    ----------
    centre : ndarray (3,)
        Projection centre (world, m).
    target : ndarray (3,)
        Point the optical axis passes through before the tilts (world, m).
    omega_deg, phi_deg, kappa_deg : float
        Small rotations about the camera's x, y and z axes, applied after aiming (degrees).

    Returns
    -------
    Pose
    """
    import cv2

    C = np.asarray(centre, float)
    z = np.asarray(target, float) - C
    z /= np.linalg.norm(z)
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    Rt = cv2.Rodrigues(np.radians([omega_deg, phi_deg, kappa_deg]).astype(float))[0]
    return Pose(R=Rt @ np.vstack([x, y, z]), C=C)


def paper_rig(H_m: float, B_m: float, centre_xy: tuple[float, float] = (0.0, 0.0),
              tilt_deg: tuple[float, float, float, float, float, float] = (0.3, -0.2, 0.4, -0.25, 0.35, -0.5),
              convergent: bool = True) -> StereoRig:
    """The paper's rig at height ``H_m`` and base ``B_m`` over ``centre_xy`` (object plane z = 0).

    Parameters
    ----------
    H_m, B_m : float
        Camera height above the object and base length (m), both > 0.
    centre_xy : (float, float)
        Point under the middle of the base (m).
    tilt_deg : six floats
        (ω, φ, κ) of the left then the right camera (deg): a real rig is never exactly
        aligned, so rectification has something to correct.
    convergent : bool
        Aim both optical axes at ``centre_xy`` on z = 0 (True) or look straight down.
        [I] The paper does not say; with B/H up to 0.42 and a 25° × 16° field of view a
        parallel pair would not both see the box, so the cameras must converge.

    Returns
    -------
    StereoRig
    """
    if not (H_m > 0 and B_m > 0):
        raise InputError(f"stereo rig: H = {H_m} m and B = {B_m} m must both be positive")
    cams = paper_cameras()
    cx, cy = centre_xy
    Cl, Cr, target = np.array([cx - B_m / 2, cy, H_m]), np.array([cx + B_m / 2, cy, H_m]), np.array([cx, cy, 0.0])
    if convergent:
        pl, pr = look_at_pose(Cl, target, *tilt_deg[:3]), look_at_pose(Cr, target, *tilt_deg[3:])
    else:
        pl, pr = nadir_pose(Cl, *tilt_deg[:3]), nadir_pose(Cr, *tilt_deg[3:])
    return StereoRig(cams["left"], cams["right"], pl, pr)


def stereo_L_m(H_m: float | np.ndarray, B_m: float | np.ndarray) -> float | np.ndarray:
    """The paper's geometry factor ``L = H²/B`` (m)."""
    return np.asarray(H_m, float) ** 2 / np.asarray(B_m, float)


def delta_z_m(H_m: float, B_m: float, camera: Camera, matching_px: float = 1.0) -> float:
    """Expected depth precision ``δz = (H/f)(H/B)·δ_CCD·matching_px`` (m), Eq. 1.

    Reuses :func:`kitegully.tether.planning.stereo_precision_m` with the camera's principal
    distance ``f·pitch`` (the calibrated one, not the nominal 50 mm); ``matching_px`` is the
    matching precision in pixels (1 px gives the paper's formula).

    Parameters
    ----------
    H_m : float
        Camera height above the object (m).
    B_m : float
        Base length (m).
    camera : Camera
        Gives the principal distance ``f·pitch`` and the pixel pitch.
    matching_px : float
        Matching precision (px).

    Returns
    -------
    float
        δz (m); infinite when ``B_m`` ≤ 0.
    """
    pc = PlanningCamera(
        sensor_width_mm=camera.sensor_width_mm, sensor_height_mm=camera.sensor_height_mm,
        image_width_px=camera.width, image_height_px=camera.height,
        focal_length_mm=camera.f * camera.pixel_pitch_mm,
    )
    return stereo_precision_m(H_m, B_m, pc) * matching_px
