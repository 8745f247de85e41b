"""The final adjustment: closed-form robust start, robust least squares, outlier removal, clean pass, diagnostics.

Steps (shared/docs/adjustment.md § Solving):
1. similarity start: Umeyama + RANSAC on (C_i → G_i) and (P_rel → P_ground) with O = 0, t_d = 0;
2. delay start: the linear 13-unknown model A·C + T = G + V·d (A a general 3×3), only a start;
3. `scipy.optimize.least_squares` on whitened residuals (analytic Jacobian: 3 rows per image × ≤ 11 columns, so
   the cost is linear in the number of images), priors as extra whitened rows, robust loss;
4. outliers: per-image χ²₃ / σ̂₀²(robust) > threshold (99.9 %), dropped; 5. a clean pass with a linear loss;
6. Σ = σ̂₀²(JᵀJ)⁻¹, σ̂₀² = Σr²/(m − n), correlations, condition number, the weakest combination, warnings;
7. GCP blunders: each GCP in turn is left out and predicted by the others (as a check point, with its propagated
   σ); the worst one whose χ²₃ exceeds the threshold is excluded and the test repeated (data snooping, one at a
   time); a σ̂₀ far above 1 afterwards flags the result (`blunder_suspected`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from ground.adjust.interpolate import interpolate_antenna
from ground.adjust.model import (
    PARAMETER_NAMES,
    AdjustmentOptions,
    AdjustmentProblem,
    AdjustmentRefused,
    AdjustmentResult,
    CheckPointResidual,
    ExcludedGcp,
)
from ground.adjust.relative import RelativePairs, consecutive_pairs
from ground.adjust.similarity import (
    DegenerateGeometry,
    ransac_umeyama,
    skew,
    so3_exp,
    so3_left_jacobian,
)
from ground.adjust.types import CameraPose, ControlPoint, ImageEvent, Trajectory

log = logging.getLogger(__name__)
Arr = npt.NDArray[np.float64]

_T, _W, _MU, _O, _TD = slice(0, 3), slice(3, 6), 6, slice(7, 10), 10
_CHI2_3_MEDIAN = 2.366  # median of χ² with 3 degrees of freedom


def build_problem(
    poses: Sequence[CameraPose],
    events: Sequence[ImageEvent],
    trajectory: Trajectory,
    control: Sequence[ControlPoint] = (),
    origin_ecef_m: npt.ArrayLike | None = None,
    max_gap_s: float = 1.5,
) -> AdjustmentProblem:
    """Match poses and events by image name, interpolate the antenna at each event, build the problem.

    Images without an event, events without a pose, and events outside the trajectory or in a gap are left out
    and listed in `skipped` with the reason. `control` must already be in the same ENU frame (about
    `origin_ecef_m`, default: the first trajectory position).
    """
    ev = {e.image: e for e in events}
    skipped: list[tuple[str, str]] = []
    matched = []
    for pose in poses:
        e = ev.get(pose.image)
        if e is None:
            skipped.append((pose.image, "no event (time mark) for this image"))
        else:
            matched.append((pose, e))
    posed = {p.image for p in poses}
    skipped.extend(
        (e.image, "event without a pose in the bundle adjustment") for e in events if e.image not in posed
    )
    if not matched:
        raise AdjustmentRefused("no image has both a pose and an event: check that image names match")
    matched, notes, dropped = _one_event_kind(matched)
    skipped.extend(dropped)
    if not matched:
        raise AdjustmentRefused("no image is left once the event kinds are reconciled: " + dropped[0][1])
    times_ns = np.array([e.time.total_ns for _, e in matched], dtype=np.int64)
    ant = interpolate_antenna(trajectory, times_ns, origin_ecef_m, max_gap_s)
    keep = np.flatnonzero(ant.valid)
    skipped.extend((matched[i][0].image, ant.reason[i]) for i in np.flatnonzero(~ant.valid))
    if keep.size == 0:
        raise AdjustmentRefused("no event falls inside the trajectory: " + "; ".join(sorted(set(ant.reason))))
    names = [matched[i][0].image for i in keep]
    t0 = int(times_ns[keep].min())
    base = AdjustmentProblem.from_arrays(
        names,
        np.array([matched[i][0].centre_rel for i in keep]),
        np.array([matched[i][0].r_cam_to_rel for i in keep]),
        ant.pos_enu_m[keep],
        ant.vel_enu_m_s[keep],
        ant.sigma_enu_m[keep],
        (times_ns[keep] - t0).astype(float) / 1e9,
        ant.quality[keep],
        tuple(control),
        ant.origin_ecef_m,
        ant.acc_enu_m_s2[keep],
    )
    return replace(base, skipped=tuple(skipped), notes=tuple(notes))


def _one_event_kind(
    matched: list[tuple[CameraPose, ImageEvent]],
) -> tuple[list[tuple[CameraPose, ImageEvent]], list[str], list[tuple[str, str]]]:
    """Bring every event to one kind, since one t_d cannot serve trigger pulses (≈ 64 ms) and flashes (≈ 0).

    A missed flash leaves its trigger pulse: the minority kind is converted to the majority kind with the image's
    own measured trigger→flash delay, else the median of those measured on this flight. With no measured delay at
    all, the minority images are skipped with the reason. Returns (events, notes, skipped).
    """
    kinds = [e.kind for _, e in matched]
    n_flash = kinds.count("flash")
    if n_flash in (0, len(kinds)):
        return matched, [], []
    majority = "flash" if 2 * n_flash >= len(kinds) else "trigger"
    measured = [e.measured_delay_s for _, e in matched if e.measured_delay_s is not None]
    if not measured:
        reason = (
            f"{'trigger' if majority == 'flash' else 'flash'} event among {majority} events, and no measured "
        )
        reason += "trigger→flash delay to convert it"
        return (
            [(p, e) for p, e in matched if e.kind == majority],
            [],
            [(p.image, reason) for p, e in matched if e.kind != majority],
        )
    median_s = float(np.median(measured))
    out = []
    converted = 0
    for pose, e in matched:
        if e.kind != majority:
            d = e.measured_delay_s if e.measured_delay_s is not None else median_s
            t = e.time.add_s(d if majority == "flash" else -d)
            e = ImageEvent(e.image, t, majority, e.measured_delay_s)
            converted += 1
        out.append((pose, e))
    note = (
        f"{converted} {'trigger' if majority == 'flash' else 'flash'} event(s) converted to {majority} times with the "
        f"measured trigger→flash delay (median {median_s * 1e3:.2f} ms over {len(measured)} image(s))"
    )
    return out, [note], []


@dataclass
class _Data:
    """Arrays of the images currently in the adjustment (a view of the problem without outliers)."""

    c: Arr
    r: Arr
    g: Arr
    v: Arr
    a: Arr
    sig: Arr  # combined σ (antenna ⊕ camera centre), ENU m
    pairs: RelativePairs | None


class _Model:
    """Residuals and analytic Jacobian over the full 11-vector; `active` selects the estimated columns."""

    def __init__(
        self,
        options: AdjustmentOptions,
        r0: Arr,
        base: Arr,
        gcps: tuple[ControlPoint, ...],
        c_bar: Arr,
        g_bar: Arr,
    ) -> None:
        self.opt = options
        # the model works on centred coordinates (relative − c̄, ENU − ḡ) so that the translation is the one of
        # the block centroid and does not correlate with the rotation; T = T' + ḡ − μ·R·c̄
        self.c_bar = c_bar
        self.g_bar = g_bar
        self.r0 = r0
        self.base = base.copy()
        act = np.zeros(11, dtype=bool)
        if options.similarity.mode != "fixed":
            act[0:7] = True
        if options.lever_arm.mode != "fixed":
            act[7:10] = True
        if options.delay.mode != "fixed":
            act[10] = True
        self.active = act
        self.gcp_rel = np.array([p.rel for p in gcps], dtype=float).reshape(-1, 3)
        self.gcp_ground = np.array([p.ground_enu_m for p in gcps], dtype=float).reshape(-1, 3)
        self.gcp_sig = np.array([p.sigma_m for p in gcps], dtype=float).reshape(-1, 3)
        self.data: _Data | None = None
        self._prior_rows()

    def _prior_rows(self) -> None:
        """Priors as whitened rows: (p[idx] − value)/σ; the rotation prior is on ω about R0 = R_prior."""
        o = self.opt
        idx: list[int] = []
        val: list[float] = []
        sig: list[float] = []
        self.t_prior: tuple[Arr, float] | None = None
        if o.similarity.mode == "prior":
            s = o.similarity
            idx += [3, 4, 5, 6]
            val += [0.0, 0.0, 0.0, s.scale]
            sig += [s.rotation_sigma_rad] * 3 + [s.scale_sigma]
            self.t_prior = (np.asarray(s.translation_m, dtype=float), s.translation_sigma_m)
        if o.lever_arm.mode == "prior":
            idx += [7, 8, 9]
            val += list(o.lever_arm.value_m)
            sig += list(o.lever_arm.sigma_m)
        if o.delay.mode == "prior":
            idx += [10]
            val += [o.delay.value_s]
            sig += [o.delay.sigma_s]
        if any(s_ <= 0 for s_ in sig):
            raise AdjustmentRefused("every prior σ must be positive (use mode 'fixed' for an exact value)")
        self.prior_idx = np.array(idx, dtype=int)
        self.prior_val = np.array(val, dtype=float)
        self.prior_sig = np.array(sig, dtype=float)

    def full(self, x: Arr) -> Arr:
        p = self.base.copy()
        p[self.active] = x
        return p

    def rotation(self, p: Arr) -> Arr:
        return so3_exp(p[_W]) @ self.r0

    def translation(self, p: Arr) -> tuple[Arr, Arr]:
        """T of the uncentred similarity (ENU m) and ∂T/∂p (3,11)."""
        rw = so3_exp(p[_W])
        y = self.r0 @ self.c_bar
        ry = rw @ y
        t = p[_T] + self.g_bar - p[_MU] * ry
        jac = np.zeros((3, 11))
        jac[:, 0:3] = np.eye(3)
        jac[:, 3:6] = p[_MU] * skew(ry) @ so3_left_jacobian(p[_W])
        jac[:, 6] = -ry
        return t, jac

    @staticmethod
    def _points(p: Arr, r0: Arr, c: Arr, r_i: Arr | None) -> tuple[Arr, Arr]:
        """e = T + exp([ω])·z − (…) with z = R0(μ·c + R_i·O); returns (T + R z (n,3), Jacobian (n,3,11))."""
        rw = so3_exp(p[_W])
        rr = rw @ r0
        mu = p[_MU]
        z = mu * c @ r0.T
        if r_i is not None:
            z = z + (r_i @ p[_O]) @ r0.T  # R0·R_i·O; matmul, not einsum (10× faster at 10⁴ images)
        rz = z @ rw.T
        jac = np.zeros((c.shape[0], 3, 11))
        jac[:, :, 0:3] = np.eye(3)
        jac[:, :, 3:6] = -skew(rz) @ so3_left_jacobian(p[_W])
        jac[:, :, 6] = c @ rr.T
        if r_i is not None:
            jac[:, :, 7:10] = rr @ r_i
        return p[_T] + rz, jac

    def image_residuals(self, p: Arr, c: Arr, r: Arr, g: Arr, v: Arr, a: Arr) -> tuple[Arr, Arr]:
        """Unwhitened e_i (n,3) and ∂e_i/∂p (n,3,11)."""
        pred, jac = self._points(p, self.r0, c, r)
        td = p[_TD]
        jac[:, :, 10] = -v - a * td
        return pred - g - v * td - 0.5 * a * td * td, jac

    def residuals_and_jacobian(self, x: Arr) -> tuple[Arr, Arr]:
        p = self.full(x)
        d = self.data
        assert d is not None
        blocks: list[Arr] = []
        jblocks: list[Arr] = []
        e, je = self.image_residuals(p, d.c, d.r, d.g, d.v, d.a)
        if d.pairs is None:
            blocks.append((e / d.sig).ravel())
            jblocks.append((je / d.sig[:, :, None]).reshape(-1, 11))
        else:
            w, jw = d.pairs.whiten(e, je)
            blocks.append(w)
            jblocks.append(jw)
        if self.gcp_rel.shape[0]:
            pred, jg = self._points(p, self.r0, self.gcp_rel, None)
            blocks.append(((pred - self.gcp_ground) / self.gcp_sig).ravel())
            jblocks.append((jg / self.gcp_sig[:, :, None]).reshape(-1, 11))
        if self.t_prior is not None:
            t, jt = self.translation(p)
            blocks.append((t - self.t_prior[0]) / self.t_prior[1])
            jblocks.append(jt / self.t_prior[1])
        if self.prior_idx.size:
            blocks.append((p[self.prior_idx] - self.prior_val) / self.prior_sig)
            jp = np.zeros((self.prior_idx.size, 11))
            jp[np.arange(self.prior_idx.size), self.prior_idx] = 1.0 / self.prior_sig
            jblocks.append(jp)
        res = np.concatenate(blocks)
        jac = np.vstack(jblocks)[:, self.active]
        return res, jac


def _tr_solver(n_unknowns: int) -> dict[str, object]:
    """least_squares trust-region solver: LSMR (no SVD of the m×n Jacobian: threaded LAPACK SVDs of tall thin
    matrices were 20× slower than the whole LSMR solve on 2 cores); scipy's LSMR path fails for one unknown."""
    if n_unknowns < 2:
        return {"tr_solver": "exact"}
    return {"tr_solver": "lsmr", "tr_options": {"atol": 1e-10, "btol": 1e-10}}


def _delay_start(c: Arr, g: Arr, v: Arr) -> float:
    """Linear 13-unknown start: G = A·C + T − V·d (A general 3×3); returns d (s), 0 when ill-posed."""
    n = c.shape[0]
    if n < 6:
        return 0.0
    cc = c - c.mean(axis=0)
    gg = g - g.mean(axis=0)
    vv = v - v.mean(axis=0)  # centring eliminates T
    a = np.zeros((3 * n, 10))
    for ax in range(3):
        a[ax::3, 3 * ax : 3 * ax + 3] = cc
        a[ax::3, 9] = -vv[:, ax]
    sol, *_ = np.linalg.lstsq(a, gg.ravel(), rcond=None)
    d = float(sol[9])
    return d if np.isfinite(d) and abs(d) < 1.0 else 0.0


def _check_refusals(problem: AdjustmentProblem, options: AdjustmentOptions) -> None:
    n_gcp = len(problem.gcps)
    if len(problem.images) == 0:
        raise AdjustmentRefused("the problem holds no image")
    if options.lever_arm.mode == "free" and n_gcp == 0:
        raise AdjustmentRefused(
            "refusing to estimate the lever arm freely with no GCP and no prior: O_z is inseparable from the "
            "vertical translation T_u (and along-track O from t_d); give the ground-calibrated lever arm as a "
            "prior (LeverArmSpec(mode='prior', value_m=…, sigma_m=…)) or add at least one GCP"
        )
    if options.relative_control and options.similarity.mode == "free" and n_gcp == 0:
        raise AdjustmentRefused(
            "relative (differenced) aerial control cancels the translation: it needs ≥ 1 GCP (or a similarity "
            "prior)"
        )


def _initial_similarity(problem: AdjustmentProblem, options: AdjustmentOptions) -> tuple[float, Arr, Arr]:
    s = options.similarity
    if s.mode != "free":
        rot = np.asarray(s.rotation, dtype=float)
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
            raise AdjustmentRefused("the similarity rotation given in the options is not a proper rotation")
        return s.scale, rot, np.asarray(s.translation_m, dtype=float)
    src = [problem.centre_rel] + [p.rel[None, :] for p in problem.gcps]
    dst = [problem.antenna_enu_m] + [p.ground_enu_m[None, :] for p in problem.gcps]
    try:
        fit, _ = ransac_umeyama(
            np.vstack(src),
            np.vstack(dst),
            options.ransac_threshold_m,
            options.ransac_iterations,
            np.random.default_rng(options.ransac_seed),
        )
    except DegenerateGeometry as exc:
        raise AdjustmentRefused(f"cannot start the similarity: {exc}") from exc
    return fit.scale, fit.rotation, fit.translation


def _covariance(jac: Arr, res: Arr, names: tuple[str, ...]) -> tuple[float, Arr, Arr, float, str, Arr]:
    """σ̂₀, Σ = σ̂₀²(JᵀJ)⁻¹, correlations, condition number (column-scaled J), weakest combination, smallest sv."""
    m, n = jac.shape
    if n == 0:
        return float(np.sqrt(res @ res / max(m, 1))), np.zeros((0, 0)), np.zeros((0, 0)), 1.0, "", np.zeros(0)
    dof = m - n
    sigma0 = float(np.sqrt(res @ res / dof)) if dof > 0 else float("nan")
    norms = np.linalg.norm(jac, axis=0)
    norms[norms < 1e-12 * max(float(norms.max()), 1e-300)] = 1.0  # an all-zero column stays ~0: singular
    _, sv, vt = np.linalg.svd(jac / norms, full_matrices=False)
    smin = sv[-1] if sv[-1] > 0 else np.finfo(float).tiny
    cond = float(sv[0] / smin)
    singular = sv < sv[0] * 1e-10
    inv_sv2 = np.zeros_like(sv)
    inv_sv2[~singular] = 1.0 / sv[~singular] ** 2
    cov_n = (vt.T * inv_sv2) @ vt
    cov = cov_n / np.outer(norms, norms) * ((sigma0**2) if np.isfinite(sigma0) else 1.0)
    if np.any(singular):
        # a null direction of J: the parameters in it are not determinable, their σ is infinite (not 0)
        involved = np.any(np.abs(vt[singular]) > 0.05, axis=0)
        cov[involved, :] = np.nan
        cov[:, involved] = np.nan
        cov[involved, involved] = np.inf
    sd = np.sqrt(np.maximum(np.nan_to_num(np.diag(cov), nan=np.inf), 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(sd, sd)
    corr = np.nan_to_num(corr, nan=0.0, posinf=0.0, neginf=0.0)
    np.fill_diagonal(corr, 1.0)
    vec = vt[-1]
    order = np.argsort(-np.abs(vec))
    terms = [f"{vec[k]:+.2f}·{names[k]}" for k in order if abs(vec[k]) >= 0.2]
    return sigma0, cov, corr, cond, " ".join(terms), vec


def _along_track_axis(problem_r: Arr, rot: Arr, v: Arr) -> int | None:
    """Camera axis (0 x, 1 y, 2 z) most aligned with the horizontal velocity, over images moving > 1 m/s."""
    speed = np.linalg.norm(v, axis=1)
    moving = speed > 1.0
    if not np.any(moving):
        return None
    r_c2w = np.einsum("ij,njk->nik", rot, problem_r[moving])
    v_cam = np.einsum("nji,nj->ni", r_c2w, v[moving] / speed[moving, None])
    return int(np.argmax(np.mean(np.abs(v_cam), axis=0)))


def adjust(problem: AdjustmentProblem, options: AdjustmentOptions | None = None) -> AdjustmentResult:
    """Estimate the similarity, lever arm and delay of `problem` (see the module docstring for the steps).

    GCPs that fail the leave-one-out test are excluded (listed in `excluded_gcps`, with a warning); a result
    whose σ̂₀ exceeds `options.blunder_sigma0` comes back with `blunder_suspected` set and a warning.
    Raises AdjustmentRefused with a clear message when the problem is not solvable as posed (free lever arm
    with no GCP and no prior; relative control without GCP; collinear geometry; too many outliers; more GCPs
    contradicting the others than `max_excluded_gcp_fraction`).
    """
    opt = options or AdjustmentOptions()
    excluded: list[ExcludedGcp] = []
    n_gcp = len(problem.gcps)
    current = problem
    untestable: list[str] = []
    while opt.gcp_blunder_test and current.gcps:
        worst, untestable = _worst_gcp(current, opt)
        if worst is None or worst.chi2 <= opt.gcp_chi2_threshold:
            break
        excluded.append(worst)
        if len(excluded) > opt.max_excluded_gcp_fraction * n_gcp:
            raise AdjustmentRefused(
                f"{len(excluded)} of {n_gcp} GCPs contradict the others ({_gcp_list(excluded)}): check their "
                "coordinates, CRS and names, that the GCP file belongs to this flight, and the base position "
                "(a GNSS bias moves every image against every GCP; relative control cancels it)"
            )
        current = replace(current, control=tuple(c for c in current.control if c.name != worst.name or
                                                 c.role != "gcp"))
    try:
        result = _adjust_once(current, opt)
    except AdjustmentRefused as exc:
        if not excluded:
            raise
        raise AdjustmentRefused(f"after excluding the GCP blunder(s) {_gcp_list(excluded)}: {exc}") from exc
    added: list[str] = []
    if blunder := bool(np.isfinite(result.sigma0) and result.sigma0 > opt.blunder_sigma0):
        added.append(f"blunder suspected: σ̂₀ = {result.sigma0:.3g} > {opt.blunder_sigma0:g} (the residuals are "
                     f"{result.sigma0:.3g}× the stated σ): a GCP, the base position or an input of another "
                     "flight is wrong")
    if excluded:
        added.append(f"{len(excluded)} GCP(s) excluded by the leave-one-out test (χ²₃ > "
                     f"{opt.gcp_chi2_threshold:.1f}): {_gcp_list(excluded)}")
    if untestable:
        added.append(f"GCP(s) {', '.join(untestable)} could not be checked by leave-one-out (the adjustment "
                     "needs them); their residuals rest on σ̂₀ alone")
    for w in added:
        log.warning("adjust: %s", w)
    return replace(result, warnings=tuple(added) + result.warnings, excluded_gcps=tuple(excluded),
                   blunder_suspected=blunder)


def _gcp_list(excluded: list[ExcludedGcp]) -> str:
    return ", ".join(f"{g.name} (off by {float(np.linalg.norm(g.residual_enu_m)):.3g} m, χ²₃ {g.chi2:.3g})"
                     for g in excluded)


def _worst_gcp(problem: AdjustmentProblem, opt: AdjustmentOptions) -> tuple[ExcludedGcp | None, list[str]]:
    """Leave-one-out over the GCPs: each is made a check point, predicted by the adjustment of the others with
    its propagated σ; returns the one of largest χ²₃ (None when none could be tested) and the untestable ones."""
    worst: ExcludedGcp | None = None
    untestable: list[str] = []
    quiet = replace(opt, gcp_blunder_test=False)
    for gcp in problem.gcps:
        control = tuple(replace(c, role="check") if c.role == "gcp" and c.name == gcp.name else c
                        for c in problem.control if c.role == "gcp" or c.name != gcp.name)
        try:
            loo = _adjust_once(replace(problem, control=control), quiet, log_warnings=False)
        except AdjustmentRefused:
            untestable.append(gcp.name)
            continue
        cp = next(c for c in loo.checkpoints if c.name == gcp.name)
        d = np.array([cp.de_m, cp.dn_m, cp.du_m])
        sd = np.maximum(np.asarray(cp.sigma_enu_m, dtype=float), 1e-9)
        chi2 = float(np.sum((d / sd) ** 2))
        if not np.isfinite(chi2):
            untestable.append(gcp.name)
            continue
        if worst is None or chi2 > worst.chi2:
            worst = ExcludedGcp(gcp.name, (float(d[0]), float(d[1]), float(d[2])), chi2)
    return worst, untestable


def _adjust_once(problem: AdjustmentProblem, opt: AdjustmentOptions,
                 log_warnings: bool = True) -> AdjustmentResult:
    """One adjustment of `problem` as given (steps 1–6 of the module docstring, no GCP test)."""
    _check_refusals(problem, opt)
    n_img = len(problem.images)
    c_bar = problem.centre_rel.mean(axis=0)
    g_bar = problem.antenna_enu_m.mean(axis=0)
    mu0, rot0, t0 = _initial_similarity(problem, opt)
    problem = _centred(problem, c_bar, g_bar)
    base = np.zeros(11)
    base[_T] = t0 + mu0 * rot0 @ c_bar - g_bar
    base[_MU] = mu0
    base[_O] = np.asarray(opt.lever_arm.value_m, dtype=float)
    if opt.delay.mode == "free":
        base[_TD] = _delay_start(problem.centre_rel, problem.antenna_enu_m, problem.velocity_enu_m_s)
    else:
        base[_TD] = opt.delay.value_s
    model = _Model(opt, rot0, base, problem.gcps, c_bar, g_bar)
    sig_all = np.sqrt(problem.antenna_sigma_enu_m**2 + opt.camera_centre_sigma_m**2)
    acc = np.zeros((n_img, 3)) if problem.acceleration_enu_m_s2 is None else problem.acceleration_enu_m_s2
    names = tuple(n for n, a in zip(PARAMETER_NAMES, model.active, strict=True) if a)

    def set_data(mask: npt.NDArray[np.bool_]) -> None:
        pairs = None
        if opt.relative_control:
            pairs = consecutive_pairs(problem.event_time_s[mask], sig_all[mask], opt.max_pair_dt_s)
            if pairs.n_pairs == 0:
                raise AdjustmentRefused(
                    f"relative control: no consecutive image pair closer than {opt.max_pair_dt_s} s"
                )
        model.data = _Data(
            problem.centre_rel[mask], problem.r_cam_to_rel[mask], problem.antenna_enu_m[mask],
            problem.velocity_enu_m_s[mask], acc[mask], sig_all[mask], pairs,
        )  # fmt: skip

    def solve(x0: Arr, loss: str) -> Arr:
        if x0.size == 0:
            return x0
        cache: dict[bytes, tuple[Arr, Arr]] = {}

        def both(x: Arr) -> tuple[Arr, Arr]:
            key = x.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = model.residuals_and_jacobian(x)
            return cache[key]

        sol = least_squares(
            lambda x: both(x)[0], x0, jac=lambda x: both(x)[1], method="trf", loss=loss, f_scale=opt.f_scale,
            x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-10, max_nfev=200, **_tr_solver(x0.size),
        )  # fmt: skip
        return np.asarray(sol.x, dtype=float)

    inlier = np.ones(n_img, dtype=bool)
    set_data(inlier)
    x = solve(base[model.active], opt.loss)
    p = model.full(x)

    # outliers: per-image χ² at the robust solution, normalised by a robust σ̂₀²
    e_all, _ = model.image_residuals(p, problem.centre_rel, problem.r_cam_to_rel, problem.antenna_enu_m,
                                     problem.velocity_enu_m_s, acc)  # fmt: skip
    if opt.relative_control:
        chi2 = _relative_image_chi2(e_all, problem.event_time_s, sig_all, opt.max_pair_dt_s)
    else:
        chi2 = np.sum((e_all / sig_all) ** 2, axis=1)
    finite = np.isfinite(chi2)
    # robust σ̂₀² from the median χ²; never below 1 so that honest σ are not tightened by the test itself
    s2 = max(float(np.median(chi2[finite])) / _CHI2_3_MEDIAN, 1.0) if np.any(finite) else 1.0
    chi2n = chi2 / s2
    outlier = finite & (chi2n > opt.chi2_threshold)
    if outlier.sum() > opt.max_outlier_fraction * n_img:
        raise AdjustmentRefused(
            f"{int(outlier.sum())} of {n_img} images are outliers (> {opt.max_outlier_fraction:.0%}): check that "
            "the events match the images and that the trajectory and the bundle adjustment belong to this flight"
        )
    inlier = ~outlier
    set_data(inlier)
    x = solve(x, "linear")
    p = model.full(x)
    res, jac = model.residuals_and_jacobian(x) if x.size else model.residuals_and_jacobian(np.zeros(0))
    sigma0, cov, corr, cond, weakest, _ = _covariance(jac, res, names)

    inflation = 1.0
    if opt.inflate_for_time_correlation and not opt.relative_control and cov.size:
        e_in, _ = model.image_residuals(p, problem.centre_rel[inlier], problem.r_cam_to_rel[inlier],
                                        problem.antenna_enu_m[inlier], problem.velocity_enu_m_s[inlier],
                                        acc[inlier])  # fmt: skip
        inflation = variance_inflation(e_in / sig_all[inlier], problem.event_time_s[inlier], len(names),
                                       opt.segment_gap_s)  # fmt: skip
        cov = cov * inflation
    rot = model.rotation(p)
    sd_full = np.zeros(11)
    sd_full[model.active] = (
        np.sqrt(np.maximum(np.nan_to_num(np.diag(cov), nan=np.inf), 0)) if cov.size else 0.0
    )
    cov_full = np.zeros((11, 11))
    if cov.size:
        cov_full[np.ix_(model.active, model.active)] = cov
    translation, jt = model.translation(p)
    translation_sigma = np.sqrt(np.maximum(np.diag(jt @ cov_full @ jt.T), 0))

    e_all, _ = model.image_residuals(p, problem.centre_rel, problem.r_cam_to_rel, problem.antenna_enu_m,
                                     problem.velocity_enu_m_s, acc)  # fmt: skip
    checkpoints, rms, mean, std = _check_points(model, p, cov_full, problem.checks)
    gcp_res: dict[str, tuple[float, float, float]] = {}
    if problem.gcps:
        pred, _ = model._points(p, model.r0, model.gcp_rel, None)
        for gcp, d in zip(problem.gcps, pred - model.gcp_ground, strict=True):
            gcp_res[gcp.name] = (float(d[0]), float(d[1]), float(d[2]))

    warnings = _warnings(problem, opt, names, corr, cond, weakest, rot, inlier, sigma0, inflation, sd_full)
    outliers = tuple((problem.images[i], float(chi2n[i])) for i in np.flatnonzero(outlier))
    if outliers:
        warnings.append(f"{len(outliers)} image(s) flagged as outliers and left out of the final pass")
    if log_warnings:
        for w in warnings:
            log.warning("adjust: %s", w)
    # the accuracy reached at each camera centre: the parameters' Σ propagated to S(C_i), ⊕ the bundle
    # adjustment's own σ of C_i, scaled by the residuals' σ̂₀ (never below the stated σ)
    _, jac_c = model._points(p, model.r0, problem.centre_rel, None)
    param_var = np.einsum("nij,jk,nik->ni", jac_c, cov_full_finite(cov_full), jac_c)
    scale_s0 = max(1.0, (sigma0 if np.isfinite(sigma0) else 1.0) * float(np.sqrt(inflation)))
    camera_sigma = np.sqrt(np.maximum(param_var, 0.0) + (scale_s0 * opt.camera_centre_sigma_m) ** 2)
    return AdjustmentResult(
        scale=float(p[_MU]),
        scale_sigma=float(sd_full[_MU]),
        rotation=rot,
        rotation_sigma_rad=sd_full[_W].copy(),
        translation_m=translation,
        translation_sigma_m=translation_sigma,
        lever_arm_m=p[_O].copy(),
        lever_arm_sigma_m=sd_full[_O].copy(),
        delay_s=float(p[_TD]),
        delay_sigma_s=float(sd_full[_TD]),
        sigma0=sigma0,
        parameter_names=names,
        covariance=cov,
        correlations=corr,
        condition_number=cond,
        weakest_combination=weakest,
        warnings=tuple(warnings),
        outliers=outliers,
        images=problem.images,
        residuals_enu_m=e_all,
        outlier_mask=outlier,
        checkpoints=checkpoints,
        checkpoint_rms_m=rms,
        checkpoint_mean_m=mean,
        checkpoint_std_m=std,
        gcp_residuals_enu_m=gcp_res,
        n_observations=int(res.size),
        variance_inflation=inflation,
        relative_control=opt.relative_control,
        camera_sigma_enu_m=camera_sigma,
    )


def cov_full_finite(cov_full: Arr) -> Arr:
    """The covariance with undeterminable entries (NaN/inf) as a very large variance, for propagation."""
    return np.nan_to_num(cov_full, nan=0.0, posinf=1e12, neginf=-1e12)


def variance_inflation(
    white_res: Arr, t_s: Arr, n_params: int, max_dt_s: float = 3.0, cap: float = 25.0
) -> float:
    """Variance inflation for time-correlated GNSS errors, by batch means over flight segments, ≥ 1.

    RTK errors are correlated over tens of seconds, so a white-noise covariance understates the σ of every
    parameter resting on segment-to-segment contrasts (cross-track lever arm from alternating headings, delay
    from speed changes, vertical terms from climb/descent). Segments are runs of images less than `max_dt_s`
    apart (survey lines, climb, descent). With white errors, n_s·m̄_s² of the whitened residual mean of a segment
    is χ²₁ per axis; their sum over segments and axes, divided by its degrees of freedom (3·segments − the
    parameters that can absorb segment means), estimates the inflation. Capped at `cap`.
    """
    n = white_res.shape[0]
    order = np.argsort(t_s, kind="stable")
    r = white_res[order]
    breaks = np.flatnonzero(np.diff(t_s[order]) > max_dt_s) + 1
    segments = [seg for seg in np.split(np.arange(n), breaks) if seg.size >= 3]
    dof = 3 * len(segments) - n_params
    if len(segments) < 3 or dof < 6:  # too few segment means to tell correlated from white errors
        return 1.0
    total = sum(float(seg.size * np.sum(r[seg].mean(axis=0) ** 2)) for seg in segments)
    return float(np.clip(total / dof, 1.0, cap))


def _centred(problem: AdjustmentProblem, c_bar: Arr, g_bar: Arr) -> AdjustmentProblem:
    """The problem with relative coordinates minus c̄ and ENU coordinates minus ḡ (control points too)."""
    control = tuple(
        ControlPoint(c.name, c.role, np.asarray(c.rel, dtype=float) - c_bar,
                     np.asarray(c.ground_enu_m, dtype=float) - g_bar, np.asarray(c.sigma_m, dtype=float))
        for c in problem.control
    )  # fmt: skip
    return replace(
        problem,
        centre_rel=problem.centre_rel - c_bar,
        antenna_enu_m=problem.antenna_enu_m - g_bar,
        control=control,
    )


def _relative_image_chi2(e: Arr, t_s: Arr, sig: Arr, max_dt_s: float) -> Arr:
    """Per-image χ² for relative control: the smaller χ² of its (up to two) adjacent differences; NaN if none."""
    order = np.argsort(t_s, kind="stable")
    out = np.full(e.shape[0], np.nan)
    es, ts, ss = e[order], t_s[order], sig[order]
    ok = np.diff(ts) < max_dt_s
    pair_chi2 = np.sum((es[1:] - es[:-1]) ** 2 / (ss[1:] ** 2 + ss[:-1] ** 2), axis=1)
    pair_chi2[~ok] = np.nan
    left = np.concatenate([[np.nan], pair_chi2])
    right = np.concatenate([pair_chi2, [np.nan]])
    both = np.fmin(left, right)  # NaN only when both are NaN
    out[order] = both
    return out


def _check_points(
    model: _Model, p: Arr, cov_full: Arr, checks: tuple[ControlPoint, ...]
) -> tuple[tuple[CheckPointResidual, ...], dict[str, float], dict[str, float], dict[str, float]]:
    """Check-point residuals S(P_rel) − P_ground with propagated σ (parameters ⊕ the point's own σ)."""
    if not checks:
        nan = float("nan")
        empty = {"e": nan, "n": nan, "u": nan, "3d": nan}
        return (), empty, dict(empty), dict(empty)
    rel = np.array([c.rel for c in checks], dtype=float)
    ground = np.array([c.ground_enu_m for c in checks], dtype=float)
    own = np.array([c.sigma_m for c in checks], dtype=float).reshape(-1, 3)
    pred, jac = model._points(p, model.r0, rel, None)
    d = pred - ground
    rows = []
    for k, c in enumerate(checks):
        cov_k = jac[k] @ cov_full @ jac[k].T + np.diag(own[k] ** 2)
        sd = np.sqrt(np.maximum(np.diag(cov_k), 0))
        rows.append(
            CheckPointResidual(
                c.name,
                float(d[k, 0]),
                float(d[k, 1]),
                float(d[k, 2]),
                float(np.linalg.norm(d[k])),
                float(np.sqrt(np.trace(cov_k))),
                (float(sd[0]), float(sd[1]), float(sd[2])),
            )
        )
    rms = {ax: float(np.sqrt(np.mean(d[:, i] ** 2))) for i, ax in enumerate("enu")}
    rms["3d"] = float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
    mean = {ax: float(np.mean(d[:, i])) for i, ax in enumerate("enu")}
    mean["3d"] = float(np.mean(np.linalg.norm(d, axis=1)))
    std = {ax: float(np.std(d[:, i], ddof=1)) if len(checks) > 1 else 0.0 for i, ax in enumerate("enu")}
    std["3d"] = float(np.std(np.linalg.norm(d, axis=1), ddof=1)) if len(checks) > 1 else 0.0
    return tuple(rows), rms, mean, std


def _warnings(
    problem: AdjustmentProblem,
    opt: AdjustmentOptions,
    names: tuple[str, ...],
    corr: Arr,
    cond: float,
    weakest: str,
    rot: Arr,
    inlier: npt.NDArray[np.bool_],
    sigma0: float,
    inflation: float,
    sd_full: Arr,
) -> list[str]:
    out: list[str] = []
    idx = {n: k for k, n in enumerate(names)}
    thr = opt.correlation_warning
    axis_names = ("O_x", "O_y", "O_z")
    along = _along_track_axis(problem.r_cam_to_rel[inlier], rot, problem.velocity_enu_m_s[inlier])
    if along is not None and axis_names[along] in idx and "t_d" in idx:
        rho = corr[idx[axis_names[along]], idx["t_d"]]
        if abs(rho) > thr:
            out.append(
                f"along-track lever arm {axis_names[along]} and shutter delay t_d are not separable "
                f"(ρ = {rho:+.3f}): with constant heading and speed they enter as (O_along − v·t_d); vary the "
                "speed, or fix/prior the lever arm or the delay (flash time marks)"
            )
    if "O_z" in idx and "T_u" in idx:
        rho = corr[idx["O_z"], idx["T_u"]]
        if abs(rho) > thr:
            out.append(
                f"vertical lever arm O_z and vertical translation T_u are correlated (ρ = {rho:+.3f}): O_z rests "
                "on the GCP heights; prefer a calibrated lever arm prior"
            )
    named = {frozenset(("O_z", "T_u"))} | ({frozenset((axis_names[along], "t_d"))} if along is not None else set())
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            if abs(corr[a, b]) > thr and frozenset((names[a], names[b])) not in named:  # named pairs said above
                out.append(f"|ρ({names[a]}, {names[b]})| = {abs(corr[a, b]):.3f} > {thr}")
    if cond > 1e10:
        out.append(
            f"not determinable from these data: {weakest} (condition {cond:.2e}); σ reported as infinite"
        )
    elif cond > 1e6:
        out.append(f"normal equations nearly singular (condition {cond:.2e}); weakest combination: {weakest}")
    not_fixed = int(np.sum(problem.quality[inlier] != 1))
    if not_fixed:
        out.append(
            f"{not_fixed} image(s) use a trajectory that is not RTK-fixed (q ≠ 1); consider relative control"
        )
    out.extend(problem.notes)
    if problem.skipped:
        out.append(
            f"{len(problem.skipped)} image(s) skipped while building the problem (no event, gap, outside)"
        )
    for k, name in enumerate(("O_x", "O_y", "O_z")):
        if name in idx and not sd_full[7 + k] < 0.05:
            out.append(
                f"lever arm {name} is practically not determined (σ = {sd_full[7 + k]:.3g} m): fix it or give a prior"
            )
    if "t_d" in idx and not sd_full[10] < 0.01:
        out.append(
            f"shutter delay t_d is practically not determined (σ = {sd_full[10]:.3g} s): fix it or give a prior"
        )
    if inflation > 2.0:
        out.append(
            f"residuals are correlated in time: covariance inflated ×{inflation:.1f} (float or unstable RTK?)"
        )
    if np.isfinite(sigma0) and sigma0 > 3.0:
        out.append(f"σ̂₀ = {sigma0:.2f}: residuals are {sigma0:.1f}× larger than the stated σ")
    if not np.isfinite(sigma0):
        out.append("no redundancy: σ̂₀ undefined, covariance uses σ̂₀ = 1")
    return out
