"""Camera spectral response from a shot of a Macbeth (ColorChecker) chart (paper 004 sect. 2.2).

A raw channel value of chart panel ``p`` is ``v_pc = Σ_λ E(λ) ρ_p(λ) S_c(λ) Δλ`` with the
illuminant ``E``, the panel reflectance ``ρ_p`` (measured by a spectroradiometer in the
paper) and the unknown channel response ``S_c``. With 24 panels and ~80 wavelengths the
system is underdetermined: like the paper (Pike; Finlayson et al.), the response is found
by non-negative least squares with a smoothness penalty on its second differences,

    min_S ||A S − v||² + λ² ||D₂ S||²   subject to S ≥ 0,

solved exactly as one NNLS problem on the stacked matrix ``[A; λ D₂]``. λ is chosen per
channel by Morozov's discrepancy principle: the smoothest response whose chart misfit is
no larger than the sensor's noise (a stated property of the camera), never by comparing
with the true curve. (Generalised cross-validation was tried first and under-smooths on
24 strongly correlated panels: it fits the noise.)

Truth for the twin: RGB from the measured Nikon D5100 sensitivities shipped with
``colour-science`` (NPL set); the NIR-converted camera (IR-cut filter removed, > 720 nm
long-pass, red Bayer channel only, as the paper's) is modelled as the D5100 red filter
stack's NIR leak: a 720 nm long-pass edge times the silicon quantum efficiency falling
towards 800 nm ([I] see :func:`nir_converted_response`).

Red and NIR peak bias of the paper's single sunlit shot (issue 18,
``benchmarks/lowcost_spectral_bias.py``): at 0.5 % raw noise the recovered red peak lies
≈ +13 nm and the NIR peak ≈ +16 nm above the truth, blue and green within 4 nm.
Noise-free data with a small weight recover all four within 3 nm, so the chart holds the
information in principle. The bias does not follow the penalty (first differences: red
+11, NIR +11 nm), the discrepancy level (+13 / +13 nm) or the grid (2.5 nm: +12 /
+16 nm); weight rules that smooth less (UPRE with the stated noise, GCV) scatter the
peaks (worst draws 40 nm) without removing the bias, the L-curve corner over-smooths the
NIR: on one shot the 24 smooth broad-band reflectances cannot resolve the D5100 red curve's
steep short-wave rise nor the NIR cut-on at realistic noise, and any smoothing moves the
maximum towards the long shoulder. The cure is data, as a laboratory calibration
collects it: ``illuminants`` adds shots under a tungsten-halogen lamp (A: its long-wave
slope reweights the panels across the red and NIR) and a triband fluorescent tube (FL11:
narrow lines at 545 and 611 nm, on the red rise), and ``frames_per_shot`` averages raw
frames of the tripod-mounted chart. With D65 + A + FL11 and 16 frames the same solver
and discrepancy rule recover all four peaks within 10 nm over 20 draws (mean red +6,
NIR +6 nm) and cut the curve error by a factor 2–4; neither addition alone does (the
benchmark's second table).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from scipy.optimize import nnls

from kitegully import InputError

#: Peak wavelengths reported by the paper (nm): B, G, R, NIR ([I] METHODS 5.5: B 470, G 530, R 606).
PAPER_PEAKS_NM = {"blue": 470.0, "green": 530.0, "red": 606.0, "nir": 740.0}


@dataclass(frozen=True)
class SpectralParams:
    """Parameters of the spectral-response recovery (``lowcost.spectral`` config section).

    Attributes
    ----------
    wl_min_nm, wl_max_nm, wl_step_nm : float
        Wavelength grid of the recovered response; the paper's spectroradiometer covered
        400–800 nm [P]; 5 nm steps resolve a 10 nm peak accuracy target ([I]).
    illuminants : tuple of str
        CIE illuminants of the chart shots, one shot each ([I] ``D65`` alone was the
        paper's sunlit shot; ``D65, A, FL11`` adds a tungsten-halogen lamp and a triband
        fluorescent tube, as a laboratory calibration would: A's long-wave slope and
        FL11's narrow lines at 545 and 611 nm weight the panels differently across the
        red rise and the NIR, which 24 smooth reflectances under one smooth light cannot
        resolve).
    relative_noise : float
        SD of the raw values of one frame as a fraction of the brightest panel's value
        ([I] 0.005: a raw 12-bit value of a bright panel carries photon noise of ≈ 0.5 %).
    frames_per_shot : int
        Raw frames averaged per shot (chart on a tripod) [I]: the noise of a shot is
        ``relative_noise / sqrt(frames_per_shot)``; 1 = a single frame.
    lambdas : tuple of float
        Candidate smoothness weights (log-spaced, relative to ``‖A‖₂``) scanned by the
        discrepancy principle.
    """

    wl_min_nm: float = 400.0
    wl_max_nm: float = 800.0
    wl_step_nm: float = 5.0
    illuminants: tuple[str, ...] = ("D65",)
    relative_noise: float = 0.005
    frames_per_shot: int = 1
    lambdas: tuple[float, ...] = tuple(np.logspace(-4, 1, 41))

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "SpectralParams":
        """Build from the config section; every key is required and checked."""
        ills = cfg["illuminants"]
        if isinstance(ills, str) or not ills:
            raise InputError(f"lowcost.spectral.illuminants: must be a non-empty list of CIE illuminant names, got {ills!r}")
        p = cls(
            wl_min_nm=float(cfg["wl_min_nm"]), wl_max_nm=float(cfg["wl_max_nm"]),
            wl_step_nm=float(cfg["wl_step_nm"]), illuminants=tuple(str(i) for i in ills),
            relative_noise=float(cfg["relative_noise"]), frames_per_shot=int(cfg["frames_per_shot"]),
        )
        if not p.wl_min_nm < p.wl_max_nm or p.wl_step_nm <= 0:
            raise InputError(f"lowcost.spectral: wavelength grid {p.wl_min_nm}–{p.wl_max_nm} nm by {p.wl_step_nm} nm is empty")
        if p.frames_per_shot < 1:
            raise InputError(f"lowcost.spectral.frames_per_shot: must be at least 1, got {cfg['frames_per_shot']!r}")
        return p

    @property
    def illuminant(self) -> str:
        """The first (daylight) illuminant: the paper's single sunlit shot."""
        return self.illuminants[0]

    @property
    def shot_noise(self) -> float:
        """Noise of one averaged shot as a fraction of its brightest panel."""
        return self.relative_noise / np.sqrt(self.frames_per_shot)

    @property
    def wavelengths(self) -> np.ndarray:
        """Wavelength grid (nm): ``wl_min_nm`` to ``wl_max_nm`` inclusive in steps of ``wl_step_nm``."""
        return np.arange(self.wl_min_nm, self.wl_max_nm + 0.5 * self.wl_step_nm, self.wl_step_nm)


def _resample(sd, wavelengths: np.ndarray) -> np.ndarray:
    """Values of a colour-science spectral distribution on ``wavelengths``; held constant
    beyond its measured range (nearest-value extrapolation)."""
    w = np.asarray(sd.wavelengths, float)
    return np.interp(wavelengths, w, np.asarray(sd.values, float))


def chart_reflectance(wavelengths: np.ndarray) -> tuple[list[str], np.ndarray]:
    """The 24 ColorChecker panels' reflectance (Ohta's measurements, 380–780 nm) on ``wavelengths``.

    Ohta's set is used because it reaches 780 nm: the NIR response can only be recovered
    where the panels' reflectances differ. Beyond 780 nm each panel keeps its 780 nm value
    ([I] reflectance of the chart's pigments is flat in the NIR plateau). Returns the
    panel names and a (24, n_wl) array.
    """
    import colour

    cc = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    names = list(cc)
    return names, np.stack([_resample(cc[n], wavelengths) for n in names])


def illuminant(name: str, wavelengths: np.ndarray) -> np.ndarray:
    """Relative spectral power of a CIE illuminant on ``wavelengths`` (max 1)."""
    import colour

    if name not in colour.SDS_ILLUMINANTS:
        raise InputError(f"lowcost.spectral.illuminant: unknown illuminant {name!r}")
    e = _resample(colour.SDS_ILLUMINANTS[name], wavelengths)
    return e / e.max()


def rgb_response(wavelengths: np.ndarray) -> np.ndarray:
    """True RGB response (n_wl, 3: red, green, blue), the Nikon D5100 of colour-science."""
    import colour

    m = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    w = np.asarray(m.wavelengths, float)
    out = np.stack([np.interp(wavelengths, w, m.values[:, i], right=0.0) for i in range(3)], axis=1)
    return out / out.max()


def nir_converted_response(wavelengths: np.ndarray, cut_on_nm: float = 720.0, edge_nm: float = 8.0,
                           qe_fall_nm: float = 60.0) -> np.ndarray:
    """True response of the NIR-converted camera's red channel (n_wl,), max 1.

    [I] A long-pass filter with its 50 % point at ``cut_on_nm`` (720 nm, the conversion's
    filter) and a logistic edge of ``edge_nm``, times silicon's quantum efficiency, which
    falls roughly exponentially with a scale of ``qe_fall_nm`` beyond 700 nm (the red
    dye is transparent there). Its peak lies a little above the cut-on (≈ 740 nm, the
    paper's recovered NIR peak).

    Parameters
    ----------
    wavelengths : ndarray (n_wl,)
        Wavelength grid (nm).
    cut_on_nm : float
        50 % point of the long-pass filter (nm).
    edge_nm : float
        Width scale of the filter's logistic edge (nm).
    qe_fall_nm : float
        Scale of the exponential fall of the quantum efficiency beyond 700 nm (nm).

    Returns
    -------
    ndarray (n_wl,)
        Response on ``wavelengths``, normalised to a maximum of 1.
    """
    lp = 1.0 / (1.0 + np.exp(-(wavelengths - cut_on_nm) / edge_nm))
    qe = np.exp(-np.clip(wavelengths - 700.0, 0, None) / qe_fall_nm)
    s = lp * qe
    return s / s.max()


def chart_design(reflectance: np.ndarray, light: np.ndarray, step_nm: float) -> np.ndarray:
    """Design matrix A (panels × wavelengths): ``A_pλ = E(λ) ρ_p(λ) Δλ``.

    Parameters
    ----------
    reflectance : ndarray (panels, n_wl)
        Panel reflectances ``ρ_p(λ)`` (:func:`chart_reflectance`).
    light : ndarray (n_wl,)
        Relative spectral power of the illuminant ``E(λ)`` (:func:`illuminant`).
    step_nm : float
        Wavelength step ``Δλ`` (nm).

    Returns
    -------
    ndarray (panels, n_wl)
        The design matrix A.
    """
    return reflectance * light[None, :] * step_nm


def simulate_chart_shot(design: np.ndarray, response: np.ndarray, relative_noise: float,
                        rng: np.random.Generator) -> np.ndarray:
    """Raw channel values of every panel (panels × channels) with Gaussian noise whose SD is
    ``relative_noise`` × the brightest panel's value of that channel.

    Parameters
    ----------
    design : ndarray (panels, n_wl)
        Design matrix of the shot (:func:`chart_design`).
    response : ndarray (n_wl, channels)
        True channel responses.
    relative_noise : float
        Noise SD as a fraction of each channel's brightest panel value.
    rng : Generator
        Random stream of the noise.

    Returns
    -------
    ndarray (panels, channels)
        Noisy raw values.
    """
    v = design @ response
    sd = relative_noise * v.max(axis=0, keepdims=True)
    return v + rng.normal(0.0, 1.0, v.shape) * sd


def simulate_averaged_shot(design: np.ndarray, response: np.ndarray, relative_noise: float, frames: int,
                           rng: np.random.Generator) -> np.ndarray:
    """Mean of ``frames`` noisy frames of one chart shot (:func:`simulate_chart_shot` each).

    Parameters
    ----------
    design : ndarray (panels, n_wl)
        Design matrix of the shot (:func:`chart_design`).
    response : ndarray (n_wl, channels)
        True channel responses.
    relative_noise : float
        Noise SD of one frame as a fraction of each channel's brightest panel value.
    frames : int
        Number of frames averaged.
    rng : Generator
        Random stream of the noise.

    Returns
    -------
    ndarray (panels, channels)
        Mean raw values of the frames.
    """
    return np.mean([simulate_chart_shot(design, response, relative_noise, rng) for _ in range(int(frames))], axis=0)


def stack_shots(designs: list[np.ndarray], shots: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Chart shots under several illuminants as one weighted system per channel.

    Each shot's rows (design and values) are divided by the shot's brightest value in that
    channel, so every row carries the same noise SD (noise is stated as a fraction of the
    brightest panel, :func:`simulate_chart_shot`) and the stacked least squares is the
    weighted one. Returns ``design`` (channels, rows, n_wl) and ``values`` (rows,
    channels); :func:`recover_response` takes them with the per-shot noise fraction.
    """
    if len(designs) != len(shots) or not designs:
        raise InputError(f"chart: {len(designs)} illuminant designs but {len(shots)} shots")
    shots = [np.asarray(v, float).reshape(len(v), -1) for v in shots]
    n_ch = shots[0].shape[1]
    scale = [np.abs(v).max(axis=0) for v in shots]                 # (channels,) per shot
    A = np.stack([np.vstack([d / sc[c] for d, sc in zip(designs, scale)]) for c in range(n_ch)])
    V = np.vstack([v / sc[None, :] for v, sc in zip(shots, scale)])
    return A, V


def _second_difference(n: int) -> np.ndarray:
    d = np.zeros((n - 2, n))
    i = np.arange(n - 2)
    d[i, i], d[i, i + 1], d[i, i + 2] = 1.0, -2.0, 1.0
    return d


def _nnls_smooth(An: np.ndarray, v: np.ndarray, D: np.ndarray, lam: float) -> np.ndarray:
    s, _ = nnls(np.vstack([An, lam * D]), np.concatenate([v, np.zeros(D.shape[0])]), maxiter=50 * An.shape[1])
    return s


def recover_response(design: np.ndarray, values: np.ndarray, noise_sd: float | np.ndarray,
                     lambdas: tuple[float, ...] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Non-negative, smooth channel responses from chart values.

    Parameters
    ----------
    design : (panels, n_wl) or (channels, rows, n_wl) array
        ``E(λ) ρ_p(λ) Δλ`` of every panel (:func:`chart_design`), or one weighted design
        per channel from several shots (:func:`stack_shots`).
    values : (panels,) or (panels, channels) array
        Raw values of the panels in each channel.
    noise_sd : float or (channels,) array
        SD of a raw value, as a fraction of the channel's brightest panel value (the
        sensor's stated noise).
    lambdas : sequence of float
        Candidate smoothness weights relative to the spectral norm of ``design``. Per
        channel the largest one whose RMS misfit does not exceed ``noise_sd`` is used
        at the 95 % level (discrepancy principle: ``n·RMS² ≤ σ²·χ²₀.₉₅(n)``, the misfit
        pure noise stays under in 95 % of shots); the smallest if none does.

    Returns
    -------
    response : (n_wl, channels) array
        Recovered responses, each normalised to a maximum of 1.
    chosen : (channels,) array
        The relative smoothness weight chosen per channel.

    Notes
    -----
    One NNLS (Lawson–Hanson) solve of size (panels + n_wl − 2) × n_wl per candidate and
    channel: O(len(lambdas)·n_wl³), well under a second for 81 wavelengths.
    """
    A3 = np.asarray(design, float)
    V = np.asarray(values, float)
    if V.ndim == 1:
        V = V[:, None]
    if A3.ndim == 2:
        A3 = np.broadcast_to(A3, (V.shape[1], *A3.shape))
    if A3.shape[0] != V.shape[1]:
        raise InputError(f"chart: {A3.shape[0]} channel designs but {V.shape[1]} channels of values")
    if A3.shape[1] != V.shape[0]:
        raise InputError(f"chart: {A3.shape[1]} panel spectra but {V.shape[0]} panel values")
    if A3.shape[1] < 3:
        raise InputError(f"chart: a spectral response needs at least 3 panels, got {A3.shape[1]}")
    D = _second_difference(A3.shape[2])
    lams = np.sort(np.asarray(lambdas, float))
    from scipy.stats import chi2

    n = A3.shape[1]
    sig = np.broadcast_to(np.asarray(noise_sd, float), (V.shape[1],)) * np.sqrt(chi2.ppf(0.95, n) / n)
    out = np.zeros((A3.shape[2], V.shape[1]))
    chosen = np.zeros(V.shape[1])
    for c in range(V.shape[1]):
        An = A3[c] / np.linalg.norm(A3[c], 2)
        v = V[:, c] / max(np.abs(V[:, c]).max(), 1e-300)
        lam, s = lams[0], _nnls_smooth(An, v, D, lams[0])
        for cand in lams[1:]:
            trial = _nnls_smooth(An, v, D, cand)
            if np.sqrt(np.mean((An @ trial - v) ** 2)) <= sig[c]:
                lam, s = cand, trial
        out[:, c] = s / max(s.max(), 1e-300)
        chosen[c] = lam
    return out, chosen


def peak_wavelength(wavelengths: np.ndarray, response: np.ndarray) -> np.ndarray:
    """Peak wavelength of each response column, refined by a parabola through the top three
    samples (sub-step precision)."""
    R = np.asarray(response, float)
    if R.ndim == 1:
        R = R[:, None]
    step = float(wavelengths[1] - wavelengths[0])
    peaks = np.empty(R.shape[1])
    for c in range(R.shape[1]):
        i = int(np.argmax(R[:, c]))
        if 0 < i < len(wavelengths) - 1:
            y0, y1, y2 = R[i - 1, c], R[i, c], R[i + 1, c]
            den = y0 - 2 * y1 + y2
            off = 0.5 * (y0 - y2) / den if den != 0 else 0.0
            peaks[c] = wavelengths[i] + np.clip(off, -0.5, 0.5) * step
        else:
            peaks[c] = wavelengths[i]
    return peaks


def curve_error(true: np.ndarray, recovered: np.ndarray) -> np.ndarray:
    """RMS difference of max-normalised response curves, per column."""
    t = np.asarray(true, float).reshape(len(true), -1)
    r = np.asarray(recovered, float).reshape(len(recovered), -1)
    t = t / t.max(axis=0, keepdims=True)
    r = r / np.maximum(r.max(axis=0, keepdims=True), 1e-300)
    return np.sqrt(np.mean((t - r) ** 2, axis=0))
