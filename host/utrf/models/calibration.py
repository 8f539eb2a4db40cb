"""Calibration: fit a finger's unknown effective parameters to measured (load, tip) data.

The paper compares its model with a static loading experiment (Sec. IV-A) and reports the
mean and max error in mm and in % of the finger's length. The parameters it does not give,
or that a real finger does not honour (a stranded rope is softer than its wire's modulus,
the "straight" pose is not exactly q = 0), are fitted here with scipy's least squares:

- ``modulus``: the tendons' effective Young's modulus (Pa), fitted on a log scale;
- ``q_offset``: a tendon-displacement offset (m) added to every row's q;
- ``radius_scale``: one factor on all guide radii (kept within what the geometry allows);
- ``actuating_length``: the actuating tendon's length (m), fitted on a log scale;
- ``tip_offset``: a shift (x, y) in m between the tracker's frame and the finger's.

Data (CSV, one row per measurement, ``#`` comments allowed): ``load_kg``, optionally ``q_m``
(default 0, the straight pose), and either the tip position ``tip_x_m``, ``tip_y_m`` or the
``deflection_m`` from the zero-payload tip (``_mm`` columns are accepted too). Deflection data
carry no pose information, so only the parameters that change the stiffness can be fitted
from them.

The boundary condition: a ``q_m`` row was held at its tendon displacement (the paper's slide
stage). A ``theta2_rad`` (or ``theta2_deg``) column instead says the finger was held at that
Joint-2 angle, as the firmware's closed loop on the Joint-2 encoder holds it: the model then
finds, per row, the q at which the loaded finger's Joint-2 angle is the row's
(:func:`hold_q`), so the actuating tendon's stretch drops out and Tendons 2 and 3 stretch
the finger. Such data have no q to offset; position data fit ``modulus`` and ``tip_offset``
by default.

Uncertainty. Without more, the fit weighs every coordinate of every row alike and takes the
standard errors from the scatter of its residuals. Position data may instead carry each row's
tip covariance (``tip_cov_m2``, (n, 2, 2), m²: how well the row's measured tip *and* the
model's prediction at its measured pose are known, e.g. a held Joint-2 angle read through a
quantising encoder moves the prediction along the tip's Jacobian). The fit then minimises the
whitened residuals (generalised least squares) and takes its standard errors from those
covariances, scaled up by sqrt(chi²/dof) when the residuals scatter more than they say (never
down); ``chi2_per_dof`` reports the check.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from utrf.models import statics
from utrf.models.geometry import FingerGeometry, GeometryError

PARAMETERS = ("modulus", "q_offset", "radius_scale", "actuating_length", "tip_offset")
DEFAULT_FIT_POSITION = ("modulus", "q_offset")
DEFAULT_FIT_POSITION_THETA2 = ("modulus", "tip_offset")
DEFAULT_FIT_DEFLECTION = ("modulus",)
_STIFFNESS_ONLY = ("modulus", "radius_scale", "actuating_length")


class CalibrationError(ValueError):
    """Calibration data or a request that cannot be fitted; the message names the cause."""


@dataclass(frozen=True)
class CalibrationData:
    load_kg: np.ndarray  # (n,)
    q_m: np.ndarray  # (n,)
    tip_m: np.ndarray | None = None  # (n, 2)
    deflection_m: np.ndarray | None = None  # (n,)
    source: str = "<data>"
    theta2_rad: np.ndarray | None = None  # (n,): held at this Joint-2 angle, not at q_m
    tip_cov_m2: np.ndarray | None = None  # (n, 2, 2): each row's tip covariance (position)

    @property
    def kind(self) -> str:
        return "position" if self.tip_m is not None else "deflection"

    @property
    def hold(self) -> str:
        """``"q"`` (tendon displacement held) or ``"theta2"`` (Joint-2 angle held)."""
        return "q" if self.theta2_rad is None else "theta2"

    def __len__(self) -> int:
        return int(self.load_kg.size)


def _number(text: str, where: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise CalibrationError(f"{where}: not a number: {text!r}") from None
    if not math.isfinite(v):
        raise CalibrationError(f"{where}: not a finite number: {text!r}")
    return v


def read_csv(path: str | Path) -> CalibrationData:
    """Read calibration data; errors name the file, line and column."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except FileNotFoundError:
        raise CalibrationError(f"{path}: no such file") from None
    numbered = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")]
    if not numbered:
        raise CalibrationError(f"{path}: no header row")
    header_line, header = numbered[0]
    columns = [c.strip() for c in next(csv.reader([header]))]
    if "load_kg" not in columns:
        raise CalibrationError(f"{path}:{header_line}: needs a load_kg column, got {columns}")
    scale: dict[str, tuple[str, float]] = {}
    for name in ("tip_x", "tip_y", "deflection", "q"):
        for suffix, factor in (("_m", 1.0), ("_mm", 1e-3)):
            if name + suffix in columns:
                scale[name] = (name + suffix, factor)
    for col, factor in (("theta2_rad", 1.0), ("theta2_deg", math.pi / 180)):
        if col in columns:
            scale["theta2"] = (col, factor)
    if "theta2" in scale and "q" in scale:
        raise CalibrationError(
            f"{path}:{header_line}: give q (held tendon displacement) or theta2 (held Joint-2 "
            "angle) per row, not both"
        )
    has_tip = "tip_x" in scale and "tip_y" in scale
    if not has_tip and "deflection" not in scale:
        raise CalibrationError(
            f"{path}:{header_line}: needs tip_x_m and tip_y_m, or deflection_m "
            f"(or the _mm forms), got {columns}"
        )
    if ("tip_x" in scale) != ("tip_y" in scale):
        raise CalibrationError(f"{path}:{header_line}: tip_x and tip_y must come together")
    rows: dict[str, list[float]] = {
        k: [] for k in ("load", "q", "theta2", "tip_x", "tip_y", "deflection")
    }
    for line_no, text in numbered[1:]:
        cells = [c.strip() for c in next(csv.reader([text]))]
        if len(cells) != len(columns):
            raise CalibrationError(
                f"{path}:{line_no}: {len(cells)} values for {len(columns)} columns"
            )
        row = dict(zip(columns, cells, strict=True))
        load = _number(row["load_kg"], f"{path}:{line_no} load_kg")
        if load < 0:
            raise CalibrationError(f"{path}:{line_no} load_kg: must be >= 0, got {load}")
        rows["load"].append(load)
        for key in ("q", "theta2", "tip_x", "tip_y", "deflection"):
            if key in scale:
                col, factor = scale[key]
                rows[key].append(_number(row[col], f"{path}:{line_no} {col}") * factor)
    n = len(rows["load"])
    if n == 0:
        raise CalibrationError(f"{path}: no data rows")
    q = np.array(rows["q"]) if "q" in scale else np.zeros(n)
    theta2 = np.array(rows["theta2"]) if "theta2" in scale else None
    if has_tip:
        tip = np.column_stack([rows["tip_x"], rows["tip_y"]])
        return CalibrationData(
            np.array(rows["load"]), q, tip_m=tip, source=str(path), theta2_rad=theta2
        )
    return CalibrationData(
        np.array(rows["load"]),
        q,
        deflection_m=np.array(rows["deflection"]),
        source=str(path),
        theta2_rad=theta2,
    )


def write_csv(data: CalibrationData, path: str | Path, comment: str = "") -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    out = [f"# {ln}" for ln in comment.splitlines()] if comment else []
    pose_col, pose = (
        ("q_m", data.q_m) if data.theta2_rad is None else ("theta2_rad", data.theta2_rad)
    )
    if data.tip_m is not None:
        out.append(f"load_kg,{pose_col},tip_x_m,tip_y_m")
        for w, q, (x, y) in zip(data.load_kg, pose, data.tip_m, strict=True):
            out.append(f"{w:.6g},{q:.9g},{x:.9g},{y:.9g}")
    else:
        assert data.deflection_m is not None
        out.append(f"load_kg,{pose_col},deflection_m")
        for w, q, d in zip(data.load_kg, pose, data.deflection_m, strict=True):
            out.append(f"{w:.6g},{q:.9g},{d:.9g}")
    path.write_text("\n".join(out) + "\n")
    return path


@dataclass(frozen=True)
class Parameters:
    """Effective parameters in SI units; ``geometry`` carries modulus, radii and length."""

    geometry: FingerGeometry
    q_offset_m: float = 0.0
    tip_offset_m: tuple[float, float] = (0.0, 0.0)


def hold_q(
    geom: FingerGeometry,
    theta2_rad: np.ndarray,
    load_kg: np.ndarray,
    model: str = statics.DEFAULT_MODEL,
    *,
    tolerance_rad: float = 1e-12,
    max_iterations: int = 50,
) -> np.ndarray:
    """The tendon displacement (m) at which the finger under each payload has the given
    Joint-2 angle: the q that a closed loop on the Joint-2 encoder ends up commanding.

    The loaded Joint-2 angle is (q − e1 − e2) / R2 (serial; q − e2 printed) with stretches
    that vary slowly with q, so q ← q − R2 (θ2(q) − θ2*) contracts quickly."""
    theta2 = np.asarray(theta2_rad, dtype=float)
    loads = np.broadcast_to(np.asarray(load_kg, dtype=float), theta2.shape)
    r2 = geom.guide_radii_m[1]
    q = theta2 * r2
    for _ in range(max_iterations):
        got = statics.solve_batch(geom, q, payload_kg=loads, model=model).theta[:, 1]
        miss = got - theta2
        q = q - r2 * miss
        if np.all(np.abs(miss) <= tolerance_rad):
            return q
    raise CalibrationError(
        f"no tendon displacement holds Joint 2 at the given angles within {tolerance_rad:g} rad "
        f"after {max_iterations} passes (largest miss {np.abs(miss).max():.3g} rad)"
    )


def _row_q(params: Parameters, data: CalibrationData, model: str) -> np.ndarray:
    if data.theta2_rad is None:
        return data.q_m + params.q_offset_m
    return hold_q(params.geometry, data.theta2_rad, data.load_kg, model)


def predict(params: Parameters, data: CalibrationData, model: str) -> np.ndarray:
    """Model tip positions (n, 2) or deflections (n,) for the data's loads and q (or held
    Joint-2 angles)."""
    q = _row_q(params, data, model)
    if data.theta2_rad is not None and data.kind == "deflection":
        # Unloaded reference at the same Joint-2 angle.
        q0 = hold_q(params.geometry, data.theta2_rad, np.zeros(len(data)), model)
        loaded = statics.solve_batch(params.geometry, q, payload_kg=data.load_kg, model=model)
        free = statics.solve_batch(params.geometry, q0, payload_kg=0.0, model=model)
        disp = loaded.tip - free.tip
        return np.hypot(disp[:, 0], disp[:, 1])
    if data.kind == "position":
        batch = statics.solve_batch(params.geometry, q, payload_kg=data.load_kg, model=model)
        return batch.tip + np.asarray(params.tip_offset_m)
    both = statics.solve_batch(
        params.geometry,
        np.concatenate([q, q]),
        payload_kg=np.concatenate([data.load_kg, np.zeros(len(data))]),
        model=model,
    )
    disp = both.tip[: len(data)] - both.tip[len(data) :]
    return np.hypot(disp[:, 0], disp[:, 1])


def errors_m(params: Parameters, data: CalibrationData, model: str) -> np.ndarray:
    """Per-row model error (m): tip distance, or |deflection difference|."""
    pred = predict(params, data, model)
    if data.kind == "position":
        assert data.tip_m is not None
        return np.hypot(*(pred - data.tip_m).T)
    assert data.deflection_m is not None
    return np.abs(pred - data.deflection_m)


@dataclass(frozen=True)
class CalibrationResult:
    model: str
    kind: str
    fitted: tuple[str, ...]
    initial: Parameters
    params: Parameters
    std_errors: dict[str, float | list[float] | None]
    errors_m: np.ndarray  # per row, after the fit
    initial_errors_m: np.ndarray  # per row, before
    condition_number: float
    warnings: tuple[str, ...]
    #: weighted fits (rows with covariances): chi² of the whitened residuals per degree of
    #: freedom; None otherwise
    chi2_per_dof: float | None = None

    @property
    def finger_length_m(self) -> float:
        return self.params.geometry.total_length_m

    @property
    def mean_error_m(self) -> float:
        return float(self.errors_m.mean())

    @property
    def max_error_m(self) -> float:
        return float(self.errors_m.max())

    def to_json(self) -> dict[str, Any]:
        g = self.params.geometry
        values: dict[str, Any] = {
            "tendon_youngs_modulus_pa": g.tendon_youngs_modulus_pa,
            "q_offset_m": self.params.q_offset_m,
            "guide_radii_m": list(g.guide_radii_m),
            "actuating_tendon_length_m": g.actuating_tendon_length_m,
            "tip_offset_m": list(self.params.tip_offset_m),
        }
        length = self.finger_length_m
        return {
            "model": self.model,
            "data_kind": self.kind,
            "rows": int(self.errors_m.size),
            "fitted": list(self.fitted),
            "parameters": values,
            "std_errors": self.std_errors,
            "mean_error_m": self.mean_error_m,
            "max_error_m": self.max_error_m,
            "mean_error_pct": 100 * self.mean_error_m / length,
            "max_error_pct": 100 * self.max_error_m / length,
            "initial_mean_error_m": float(self.initial_errors_m.mean()),
            "initial_max_error_m": float(self.initial_errors_m.max()),
            "finger_length_m": length,
            "condition_number": self.condition_number,
            "chi2_per_dof": self.chi2_per_dof,
            "warnings": list(self.warnings),
        }


def _max_radius_scale(geom: FingerGeometry) -> float:
    L, R = geom.link_lengths_m, geom.guide_radii_m
    return min(L[0] / (R[0] + R[1]), L[1] / (R[1] + R[2]))


def fit(
    data: CalibrationData,
    geom: FingerGeometry,
    *,
    fit_params: Sequence[str] | None = None,
    model: str = statics.DEFAULT_MODEL,
    initial: Parameters | None = None,
) -> CalibrationResult:
    """Least-squares fit of ``fit_params`` (default: modulus and q_offset for positions, the
    modulus for deflections), starting from ``initial`` (default: ``geom`` as it is)."""
    statics.require_model(model)
    names = tuple(fit_params) if fit_params is not None else None
    if names is None:
        if data.kind == "deflection":
            names = DEFAULT_FIT_DEFLECTION
        elif data.hold == "theta2":
            names = DEFAULT_FIT_POSITION_THETA2
        else:
            names = DEFAULT_FIT_POSITION
    if not names:
        raise CalibrationError("nothing to fit: give at least one parameter")
    for n in names:
        if n not in PARAMETERS:
            raise CalibrationError(f"unknown parameter {n!r}; choose from {PARAMETERS}")
    if len(set(names)) != len(names):
        raise CalibrationError(f"parameters listed twice: {list(names)}")
    if data.hold == "theta2" and "q_offset" in names:
        raise CalibrationError(
            "q_offset needs data held at a tendon displacement (q_m); these rows were held at "
            "a Joint-2 angle (theta2), which has no q to offset"
        )
    if data.kind == "deflection":
        bad = [n for n in names if n not in _STIFFNESS_ONLY]
        if bad:
            raise CalibrationError(
                f"deflection data cannot fit {bad}: they need tip positions; "
                f"fit from {list(_STIFFNESS_ONLY)}"
            )
    whiten = _whitening(data)
    start = initial if initial is not None else Parameters(geom)
    base = start.geometry
    n_unknowns = sum(2 if n == "tip_offset" else 1 for n in names)
    n_residuals = len(data) * (2 if data.kind == "position" else 1)
    if n_residuals < n_unknowns:
        raise CalibrationError(
            f"{n_residuals} residuals cannot fit {n_unknowns} unknowns ({list(names)})"
        )

    # Scaled unknowns: logs for positive scale parameters, mm for offsets.
    x0: list[float] = []
    lo: list[float] = []
    hi: list[float] = []
    for n in names:
        if n == "modulus":
            x0.append(math.log(base.tendon_youngs_modulus_pa))
            lo.append(math.log(1e8))
            hi.append(math.log(1e13))
        elif n == "q_offset":
            x0.append(start.q_offset_m * 1e3)
            lo.append(-np.inf)
            hi.append(np.inf)
        elif n == "radius_scale":
            x0.append(0.0)
            lo.append(math.log(0.05))
            hi.append(math.log(_max_radius_scale(base)) - 1e-9)
        elif n == "actuating_length":
            x0.append(math.log(base.actuating_tendon_length_m))
            lo.append(math.log(1e-3))
            hi.append(math.log(10.0))
        elif n == "tip_offset":
            x0 += [start.tip_offset_m[0] * 1e3, start.tip_offset_m[1] * 1e3]
            lo += [-np.inf, -np.inf]
            hi += [np.inf, np.inf]

    def unpack(x: np.ndarray) -> Parameters:
        g = base
        q_off, tip_off = start.q_offset_m, start.tip_offset_m
        i = 0
        changes: dict[str, Any] = {}
        for n in names:
            if n == "modulus":
                changes["tendon_youngs_modulus_pa"] = math.exp(x[i])
            elif n == "q_offset":
                q_off = x[i] * 1e-3
            elif n == "radius_scale":
                changes["guide_radii_m"] = tuple(r * math.exp(x[i]) for r in base.guide_radii_m)
            elif n == "actuating_length":
                changes["actuating_tendon_length_m"] = math.exp(x[i])
            elif n == "tip_offset":
                tip_off = (x[i] * 1e-3, x[i + 1] * 1e-3)
                i += 1
            i += 1
        if changes:
            g = replace(base, **changes)
        return Parameters(g, q_off, tip_off)

    def residuals(x: np.ndarray) -> np.ndarray:
        p = unpack(x)
        pred = predict(p, data, model)
        if data.kind == "position":
            assert data.tip_m is not None
            if whiten is not None:  # in standard deviations of each row
                return np.einsum("nij,nj->ni", whiten, pred - data.tip_m).ravel()
            return ((pred - data.tip_m) * 1e3).ravel()  # mm, for conditioning
        assert data.deflection_m is not None
        return (pred - data.deflection_m) * 1e3

    from scipy.optimize import least_squares  # here: every CLI start imports this module

    x0a = np.clip(np.array(x0), np.array(lo) + 1e-12, np.array(hi) - 1e-12)
    try:
        sol = least_squares(
            residuals, x0a, bounds=(lo, hi), method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12
        )
    except GeometryError as exc:  # pragma: no cover - bounds keep the geometry valid
        raise CalibrationError(f"the fit left the valid geometry: {exc}") from None
    fitted = unpack(sol.x)

    # Standard errors from the Jacobian (mm residuals, or whitened ones), mapped back to SI.
    jac = np.asarray(sol.jac)
    sv = np.linalg.svd(jac, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    dof = n_residuals - n_unknowns
    warnings: list[str] = []
    std: dict[str, float | list[float] | None] = {}
    cov = None
    chi2_per_dof = 2 * sol.cost / dof if whiten is not None and dof > 0 else None
    if dof > 0 and math.isfinite(cond) and cond < 1e10:
        # Weighted: the rows' covariances say how well each is known; the residuals' scatter
        # only ever widens that (a model or a covariance that falls short).
        s2 = 2 * sol.cost / dof if whiten is None else max(1.0, 2 * sol.cost / dof)
        cov = np.linalg.inv(jac.T @ jac) * s2
    if cond >= 1e8:
        warnings.append(
            f"the data barely separate {list(names)} (Jacobian condition number {cond:.2g}): "
            "fit fewer parameters or add loads / poses"
        )
    i = 0
    for n in names:
        width = 2 if n == "tip_offset" else 1
        if cov is None:
            std[n] = None
        else:
            sd = np.sqrt(np.diag(cov)[i : i + width])
            if n == "modulus":
                std[n] = float(fitted.geometry.tendon_youngs_modulus_pa * sd[0])
            elif n == "radius_scale":
                std[n] = float(math.exp(sol.x[i]) * sd[0])
            elif n == "actuating_length":
                std[n] = float(fitted.geometry.actuating_tendon_length_m * sd[0])
            elif n == "q_offset":
                std[n] = float(sd[0] * 1e-3)
            else:
                std[n] = (sd * 1e-3).tolist()
        i += width
    if dof == 0:
        warnings.append("as many unknowns as residuals: the fit is exact and has no error bars")
    if not sol.success:
        warnings.append(f"least squares stopped early: {sol.message}")
    return CalibrationResult(
        model=model,
        kind=data.kind,
        fitted=names,
        initial=start,
        params=fitted,
        std_errors=std,
        errors_m=errors_m(fitted, data, model),
        initial_errors_m=errors_m(start, data, model),
        condition_number=cond,
        warnings=tuple(warnings),
        chi2_per_dof=chi2_per_dof,
    )


def _whitening(data: CalibrationData) -> np.ndarray | None:
    """Per row, the matrix W with W C Wᵀ = I for the row's tip covariance C (m²); None when
    the data carry none. Errors name the bad row."""
    cov = data.tip_cov_m2
    if cov is None:
        return None
    if data.kind != "position":
        raise CalibrationError("tip_cov_m2 goes with tip positions, not with deflections")
    cov = np.asarray(cov, dtype=float)
    if cov.shape != (len(data), 2, 2):
        raise CalibrationError(
            f"tip_cov_m2 must be one 2 x 2 covariance per row, shape ({len(data)}, 2, 2); "
            f"got {cov.shape}"
        )
    out = np.empty_like(cov)
    for i, c in enumerate(cov):
        if not (np.all(np.isfinite(c)) and np.allclose(c, c.T, rtol=1e-9, atol=0.0)):
            raise CalibrationError(f"tip_cov_m2 row {i}: not a finite symmetric matrix: {c}")
        try:
            out[i] = np.linalg.inv(np.linalg.cholesky(c))
        except np.linalg.LinAlgError:
            raise CalibrationError(
                f"tip_cov_m2 row {i}: not positive definite (a row known exactly cannot be "
                f"weighed): {c}"
            ) from None
    return out


def synthesize(
    params: Parameters,
    loads_kg: Sequence[float],
    *,
    q_m: float | Sequence[float] = 0.0,
    kind: str = "position",
    model: str = statics.DEFAULT_MODEL,
    noise_m: float = 0.0,
    seed: int = 0,
) -> CalibrationData:
    """Data a finger with ``params`` would give, with Gaussian noise of ``noise_m`` per axis.

    For tests and examples only: the output is a model's, not a measurement.
    """
    if kind not in ("position", "deflection"):
        raise CalibrationError(f"kind must be 'position' or 'deflection', got {kind!r}")
    loads = np.asarray(loads_kg, dtype=float)
    q = np.broadcast_to(np.asarray(q_m, dtype=float), loads.shape).copy()
    rng = np.random.default_rng(seed)
    if kind == "position":
        stub = CalibrationData(loads, q, tip_m=np.zeros((loads.size, 2)))
        tip = predict(params, stub, model) + rng.normal(0.0, noise_m, (loads.size, 2))
        return CalibrationData(loads, q, tip_m=tip, source="<synthetic>")
    stub = CalibrationData(loads, q, deflection_m=np.zeros(loads.size))
    d = predict(params, stub, model) + rng.normal(0.0, noise_m, loads.size)
    return CalibrationData(loads, q, deflection_m=d, source="<synthetic>")
