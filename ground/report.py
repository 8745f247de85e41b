"""Self-contained HTML report of an adjustment: parameters with σ, correlation heat map, residuals per image,
check-point table and the trajectory coloured by fix status. Figures are inline base64 PNGs (no external
assets, opens offline). matplotlib is used through `Figure` objects only (no pyplot global state).
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ground.adjust.model import AdjustmentProblem
from ground.adjust.types import Trajectory
from onboard.formats.atomic import write_atomic
from onboard.rtk.geodesy import ecef_to_enu

Q_COLOURS = {1: ("fix", "#2ca02c"), 2: ("float", "#ff7f0e"), 5: ("single", "#d62728")}


UNDETERMINED = "undetermined"


def _v(value: float | None, scale: float = 1.0, fmt: str = ".1f") -> str:
    """A number of the results for display; None/non-finite (an undeterminable parameter's σ) says so."""
    if value is None or not np.isfinite(value):
        return UNDETERMINED
    return format(value * scale, fmt)


def figure_data_uri(fig: Figure) -> str:
    """A figure as an inline PNG `data:` URI (the report's and the web pages' one encoding of a figure)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=96, bbox_inches="tight")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _img(fig: Figure, alt: str) -> str:
    return f'<figure><img alt="{html.escape(alt)}" src="{figure_data_uri(fig)}"><figcaption>{html.escape(alt)}</figcaption></figure>'


def correlation_figure(names: list[str], matrix: np.ndarray) -> Figure:
    """Heat map of the parameter correlation matrix (−1 … 1)."""
    n = max(len(names), 1)
    fig = Figure(figsize=(1.0 + 0.45 * n, 0.8 + 0.45 * n))
    ax = fig.add_subplot()
    im = ax.imshow(matrix if matrix.size else np.zeros((1, 1)), vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(len(names)), names, rotation=90)
    ax.set_yticks(range(len(names)), names)
    for i in range(len(names)):
        for j in range(len(names)):
            if abs(matrix[i, j]) >= 0.9 and i != j:
                ax.text(j, i, f"{matrix[i, j]:.2f}", ha="center", va="center", fontsize=6)
    fig.colorbar(im, ax=ax, shrink=0.8, label="ρ")
    ax.set_title("parameter correlations (|ρ| ≥ 0.9 annotated)")
    return fig


def residual_figures(residuals: list[dict[str, Any]], centres_enu: np.ndarray | None) -> list[Figure]:
    """Per-image residuals: E/N/U against image order (outliers marked), and a horizontal vector map."""
    e = np.array([[r["e_m"], r["n_m"], r["u_m"]] for r in residuals], dtype=float).reshape(-1, 3) * 100.0
    out = np.array([r["outlier"] for r in residuals], dtype=bool)
    fig = Figure(figsize=(9, 5))
    axes = fig.subplots(3, 1, sharex=True)
    idx = np.arange(e.shape[0])
    for k, (ax, label) in enumerate(zip(axes, ("East", "North", "Up"))):
        ax.bar(idx, e[:, k], color=np.where(out, "#d62728", "#1f77b4"))
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(f"{label} (cm)")
    axes[-1].set_xlabel("image (in time order); red = outlier")
    axes[0].set_title("residuals e_i = S(C_i) + R·R_i·O − G_i − V_i·t_d per image")
    figs = [fig]
    if centres_enu is not None and centres_enu.shape[0] == e.shape[0]:
        # figure shaped like the block so that the equal-aspect map, its colour bar and the title do not collide
        span = np.maximum(np.ptp(centres_enu[:, :2], axis=0), 1.0)
        aspect = float(np.clip(span[1] / span[0], 0.25, 2.0))
        fig2 = Figure(figsize=(8, 1.6 + 6.4 * aspect), layout="constrained")
        ax = fig2.add_subplot()
        e_max_cm = max(float(np.nan_to_num(np.nanmax(np.abs(e[:, :2])))), 1e-3)
        scale = max(float(np.ptp(centres_enu[:, :2])) / 20.0, 1e-3) / e_max_cm  # metres of map per cm
        ax.quiver(centres_enu[:, 0], centres_enu[:, 1], e[:, 0] * scale, e[:, 1] * scale, angles="xy",
                  scale_units="xy", scale=1, color=np.where(out, "#d62728", "#1f77b4"))
        lim = max(float(np.nan_to_num(np.nanmax(np.abs(e[:, 2])))), 1e-3)
        sc = ax.scatter(centres_enu[:, 0], centres_enu[:, 1], c=e[:, 2], cmap="RdBu_r", s=14, vmin=-lim, vmax=lim)
        fig2.colorbar(sc, ax=ax, label="Up residual (cm)", shrink=0.8, aspect=30)
        ax.set_aspect("equal")
        ax.set_xlabel("East (m)")
        ax.set_ylabel("North (m)")
        ax.set_title(f"horizontal residuals at the camera centres (arrows: 1 cm drawn as {scale:.2g} m; "
                     "dots: Up residual)", fontsize=10)
        figs.append(fig2)
    return figs


def delay_comparison_figure(residuals: list[dict[str, Any]], velocity_enu_m_s: np.ndarray, delay_s: float) -> Figure:
    """|e_i| per image with the estimated delay and with t_d = 0 (e_i + V_i·t_d), as Daakir et al. 2015 fig. 9."""
    e = np.array([[r["e_m"], r["n_m"], r["u_m"]] for r in residuals], dtype=float).reshape(-1, 3)
    without = e + velocity_enu_m_s * delay_s
    fig = Figure(figsize=(9, 3.2))
    ax = fig.add_subplot()
    idx = np.arange(e.shape[0])
    ax.plot(idx, np.linalg.norm(without, axis=1) * 100, "o-", ms=3, color="#d62728", label="t_d = 0 (other parameters kept)")
    ax.plot(idx, np.linalg.norm(e, axis=1) * 100, "o-", ms=3, color="#1f77b4",
            label=f"t_d = {delay_s * 1000:.1f} ms (estimated)")
    ax.set_xlabel("image (in time order)")
    ax.set_ylabel("|e_i| (cm)")
    ax.legend(fontsize=8)
    ax.set_title("residual norm per image with and without the shutter delay")
    return fig


def trajectory_figure(traj: Trajectory, origin_ecef_m: np.ndarray, cams_enu: np.ndarray | None) -> Figure:
    """Trajectory (E/N about the origin) coloured by RTKLIB quality; camera positions on top."""
    enu = ecef_to_enu(traj.pos_ecef_m, origin_ecef_m)
    fig = Figure(figsize=(7, 6))
    ax = fig.add_subplot()
    q = np.asarray(traj.q)
    for code, (label, colour) in Q_COLOURS.items():
        m = q == code
        if m.any():
            ax.scatter(enu[m, 0], enu[m, 1], s=3, c=colour, label=f"{label} ({100 * m.mean():.1f} %)")
    other = ~np.isin(q, list(Q_COLOURS))
    if other.any():
        ax.scatter(enu[other, 0], enu[other, 1], s=3, c="grey", label=f"other ({100 * other.mean():.1f} %)")
    if cams_enu is not None:
        ax.scatter(cams_enu[:, 0], cams_enu[:, 1], marker="^", s=18, facecolors="none", edgecolors="k",
                   label="cameras")
    ax.set_aspect("equal")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)  # outside: never over the track
    ax.set_title("antenna trajectory by fix status")
    return fig


def _how(spec: dict[str, Any] | None, key: str, k: int | None, scale: float, unit: str) -> str:
    """How a parameter entered the adjustment, from results.json `inputs` (free / prior v ± σ / fixed)."""
    if not spec:
        return ""
    if spec.get("mode") == "free":
        return "estimated (free)"
    value = spec[f"value_{key}"] if k is None else spec[f"value_{key}"][k]
    sigma = spec[f"sigma_{key}"] if k is None else spec[f"sigma_{key}"][k]
    if spec.get("mode") == "prior":
        return f"estimated, prior {value * scale:.1f} ± {sigma * scale:.1f} {unit}"
    return "fixed (given)"


def _parameter_rows(res: dict[str, Any]) -> list[tuple[str, str, str, str, str]]:
    inputs = res.get("inputs") or {}
    free = "estimated (free)" if inputs else ""
    rows = []
    for k, axis in enumerate("xyz"):
        rows.append((f"lever arm O_{axis}", _v(res["lever_arm_m"][k], 1000), _v(res["lever_arm_sigma_m"][k], 1000),
                     "mm", _how(inputs.get("lever_arm"), "m", k, 1000, "mm")))
    rows.append(("shutter delay t_d", _v(res["delay_s"], 1000, ".2f"), _v(res["delay_sigma_s"], 1000, ".2f"), "ms",
                 _how(inputs.get("delay"), "s", None, 1000, "ms")))
    rows.append(("scale μ", _v(res["scale"], 1, ".7f"), _v(res["scale_sigma"], 1e6), "ppm", free))
    for k, axis in enumerate("ENU"):
        rows.append((f"translation T_{axis}", _v(res["translation_m"][k], 1, ".4f"),
                     _v(res["translation_sigma_m"][k], 1, ".4f"), "m", free))
    for k, axis in enumerate("ENU"):
        sig = res["rotation_sigma_rad"][k]
        rows.append((f"rotation about {axis} (matrix in results.json)", "—",
                     _v(None if sig is None else np.degrees(sig), 3600), "arcsec", free))
    rows.append(("σ̂₀ (a-posteriori, 1 = residuals as large as their stated σ)", _v(res["sigma0"], 1, ".3f"), "",
                 "", ""))
    if "variance_inflation" in res:  # serial correlation of the trajectory errors (σ inflated by its root)
        rows.append(("variance inflation for time-correlated GNSS errors (σ above include it)",
                     _v(res["variance_inflation"], 1, ".2f"), "", "", ""))
    return rows


def _summary(res: dict[str, Any]) -> str:
    """One paragraph a surveyor reads first: what went in, what came out, where the exports are."""
    inputs = res.get("inputs") or {}
    n_gcp = len(res.get("gcp_residuals") or [])
    n_chk = len(res.get("checkpoints") or [])
    rms = (res.get("checkpoint_rms_m") or {}).get("3d")
    items = [
        (f"{res['n_images']} images adjusted, {len(res['outliers'])} flagged as outliers (left out of the final "
         f"pass), {len(res.get('skipped') or [])} left out while matching"),
        f"{n_gcp} GCP(s) in the adjustment; {n_chk} check point(s) kept out of it"
        + (f": 3D RMS {_v(rms, 100, '.1f')} cm" if n_chk else ""),
        "aerial control: " + ("relative (differenced between consecutive images)" if res.get("relative_control")
                              else "absolute (antenna positions)"),
    ]
    if inputs:
        items.append(f"frames: adjustment in local ENU about ECEF {', '.join(f'{v:.3f}' for v in inputs['origin_ecef_m'])}"
                     f" m; exports in {inputs['export_crs']}")
    items.append("sign convention: lever arm O = antenna phase centre − optical centre, camera frame x right, "
                 "y down, z forward (along the viewing direction); t_d = event time → exposure")
    return "<ul id=\"summary\">" + "".join(f"<li>{html.escape(i)}</li>" for i in items) + "</ul>"


def _table(headers: list[str], rows: list[tuple[Any, ...]], table_id: str) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f'<table id="{table_id}"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def render_report(res: dict[str, Any], problem: AdjustmentProblem | None = None, trajectory: Trajectory | None = None,
                  origin_ecef_m: np.ndarray | None = None) -> str:
    """The report as one HTML string (figures inline)."""
    names = list(res["correlations"]["names"])
    matrix = np.array(res["correlations"]["matrix"], dtype=float).reshape(len(names), len(names))  # None → NaN
    cams_enu = None
    if problem is not None:
        rot = np.array(res["rotation"], dtype=float)
        cams_enu = np.asarray(res["translation_m"]) + res["scale"] * problem.centre_rel @ rot.T
    parts = [
        _summary(res),
        "<h2>Parameters</h2>",
        _table(["parameter", "value", "σ", "unit", "how"], _parameter_rows(res), "parameters"),
        (f"<p>condition number {_v(res['condition_number'], 1, '.3g')}; weakest combination: "
         f"{html.escape(str(res['weakest_combination']))}</p>"),
    ]
    if res["warnings"]:
        parts.append("<h3>Warnings</h3><ul>" + "".join(f"<li>{html.escape(w)}</li>" for w in res["warnings"]) + "</ul>")
    parts += ["<h2>Correlations</h2>", _img(correlation_figure(names, matrix), "correlation heat map")]
    parts.append("<h2>Residuals per image</h2>")
    parts += [_img(f, alt) for f, alt in zip(residual_figures(res["residuals"], cams_enu),
                                            ("residuals per image (E, N, U)", "horizontal residual map"))]
    if problem is not None and len(res["residuals"]) == len(problem.images) and res["delay_s"] is not None:
        parts.append(_img(delay_comparison_figure(res["residuals"], problem.velocity_enu_m_s, res["delay_s"]),
                          "residual norm with and without the delay"))
    if res["outliers"]:
        parts.append(_table(["outlier image", "χ²"], [(o["image"], _v(o["chi2"])) for o in res["outliers"]],
                            "outliers"))
    if res.get("gcp_residuals"):
        parts.append("<h2>GCP residuals</h2><p>S(P_rel) − P_ground of the GCPs used in the adjustment</p>")
        parts.append(_table(["GCP", "δE (cm)", "δN (cm)", "δU (cm)"],
                            [(g["name"], *(_v(g[k], 100) for k in ("de_m", "dn_m", "du_m")))
                             for g in res["gcp_residuals"]], "gcps"))
    parts.append("<h2>Check points</h2><p>independent: never in the adjustment; δ = adjusted − surveyed, "
                 "σ propagated from the parameters and the point's own σ</p>")
    if res["checkpoints"]:
        rows: list[tuple[str, ...]] = [
            (c["name"], *(_v(c[k], 100) for k in ("de_m", "dn_m", "du_m", "abs_m", "sigma_m")))
            for c in res["checkpoints"]
        ]
        for stat in ("mean", "std", "rms"):
            d = res[f"checkpoint_{stat}_m"]
            rows.append((stat, *(_v(d.get(k), 100) for k in ("e", "n", "u", "3d")), ""))
        parts.append(_table(["point", "δE (cm)", "δN (cm)", "δU (cm)", "|δ| (cm)", "σ (cm)"], rows, "checkpoints"))
    else:
        parts.append("<p>no check points</p>")
    if trajectory is not None and origin_ecef_m is not None:
        parts += ["<h2>Trajectory</h2>", _img(trajectory_figure(trajectory, origin_ecef_m, cams_enu),
                                              "trajectory coloured by fix status")]
    if res.get("skipped"):
        parts.append("<h2>Images left out</h2>" + _table(["image", "reason"], [(s["image"], s["reason"])
                                                                              for s in res["skipped"]], "skipped"))
    style = ("body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}"
             "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:2px 8px;"
             "text-align:right}td:first-child,th:first-child,#parameters td:last-child,#parameters th:last-child{text-align:left}th{background:#eee}img{max-width:100%}figcaption{font-size:small;color:#555}")
    title = f"directgeo adjustment report — {res['n_images']} images"
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
            f"<style>{style}</style></head><body><h1>{html.escape(title)}</h1>{''.join(parts)}</body></html>")


def write_report(path: str | Path, res: dict[str, Any], problem: AdjustmentProblem | None = None,
                 trajectory: Trajectory | None = None, origin_ecef_m: np.ndarray | None = None) -> None:
    """Write the self-contained HTML report (atomically: a failure leaves the previous report)."""
    write_atomic(path, render_report(res, problem, trajectory, origin_ecef_m))
