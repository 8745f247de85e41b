"""`python -m ground adjust` end to end on a synthetic flight written in the real formats (truth in, truth out),
the value/σ/--estimate rules, exports in a projected CRS, and the failure exits."""

from __future__ import annotations

import datetime as dt
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ground.cli import main
from ground.io import crs as crsmod
from ground.io.orientations import read_micmac_folder, read_opk_csv
from ground.pipeline import AdjustJobOptions, parameter_specs
from onboard.errors import InputError
from tests.ground_io.flightgen import ORIGIN_ECEF, write_synthetic_flight

pytest.importorskip("ground.adjust.solve")


def _args(d: Path, *extra: str) -> list[str]:
    return ["adjust", "--trajectory", str(d / "SOL.pos"), "--events", str(d / "events.csv"),
            "--orientations", str(d / "poses.csv"), "--gcp", str(d / "gcp.csv"), "-o", str(d / "out"), *extra]


def test_parameter_rules() -> None:
    """Value alone → fixed; value + σ → prior; nothing → free; --estimate with a value but no σ → error."""
    lever, delay = parameter_specs(AdjustJobOptions())
    assert lever.mode == "free" and delay.mode == "free"
    r = AdjustJobOptions(lever_arm_m=(0.1, 0.0, -0.1), delay_s=0.06, delay_sigma_s=0.002)
    lever, delay = parameter_specs(r)
    assert lever.mode == "fixed" and lever.value_m == (0.1, 0.0, -0.1)
    assert delay.mode == "prior" and delay.sigma_s == 0.002
    with pytest.raises(InputError, match="lever-arm-sigma"):
        parameter_specs(AdjustJobOptions(lever_arm_m=(0, 0, 0), estimate=("lever-arm",)))
    with pytest.raises(ValueError, match="estimate 'scale': must be one of lever-arm, delay"):
        AdjustJobOptions(estimate=("scale",))
    with pytest.raises(InputError, match="needs --delay"):
        parameter_specs(AdjustJobOptions(delay_sigma_s=0.001))


@pytest.mark.slow
def test_adjust_free_recovers_truth_and_exports_utm(tmp_path: Path) -> None:
    truth = write_synthetic_flight(tmp_path)
    assert main(_args(tmp_path, "--estimate", "lever-arm,delay", "--crs", "EPSG:32630")) == 0
    res = json.loads((tmp_path / "out" / "results.json").read_text())
    np.testing.assert_allclose(res["lever_arm_m"], truth.lever_arm_m, atol=4 * max(res["lever_arm_sigma_m"]) + 0.002)
    assert res["delay_s"] == pytest.approx(truth.delay_s, abs=4 * res["delay_sigma_s"] + 0.001)
    assert res["n_images"] == truth.n_images and res["inputs"]["lever_arm"]["mode"] == "free"
    issue_keys = {"lever_arm_m", "lever_arm_sigma_m", "delay_s", "delay_sigma_s", "scale", "rotation",
                  "translation_m", "sigma0", "correlations", "warnings", "outliers", "checkpoints",
                  "checkpoint_rms_m"}  # the list of issue 4, build item 6
    assert issue_keys <= set(res) and {"names", "matrix"} <= set(res["correlations"])
    assert all({"name", "de_m", "dn_m", "du_m", "abs_m", "sigma_m"} <= set(c) for c in res["checkpoints"])
    assert set(res["checkpoint_rms_m"]) == {"e", "n", "u", "3d"} and np.array(res["rotation"]).shape == (3, 3)
    assert len(res["checkpoints"]) == 2 and max(abs(c["abs_m"]) for c in res["checkpoints"]) < 0.05
    # exports: OPK CSV in UTM 30N; its centres, taken back to ENU, are the antenna minus the lever arm
    opk = read_opk_csv(tmp_path / "out" / "exports" / "opk.csv")
    assert opk.crs == "EPSG:32630"
    geo = (tmp_path / "out" / "exports" / "geo.txt").read_text().splitlines()
    assert geo[0] == "EPSG:32630" and len(geo) == truth.n_images + 1
    enu = crsmod.crs_to_enu(np.array([p.centre_rel for p in opk.poses]), "EPSG:32630", ORIGIN_ECEF)
    from tests.ground_io.flightgen import START, antenna_enu

    t_exp = np.array([float(line.split(",")[2]) for line in
                      (tmp_path / "events.csv").read_text().splitlines()[1:]]) - START.tow_s + truth.delay_s
    g, _, _ = antenna_enu(t_exp)
    # camera centre = antenna − R·O: at most |O| (0.15 m) plus noise from the antenna
    dist = np.linalg.norm(enu - g, axis=1)
    assert np.all(np.abs(dist - np.linalg.norm(truth.lever_arm_m)) < 0.05)
    # the MicMac export reads back with the same poses
    mm = read_micmac_folder(tmp_path / "out" / "exports" / "Ori-directgeo").by_image()
    for p in opk.poses:
        np.testing.assert_allclose(mm[p.image].centre_rel, p.centre_rel, atol=1e-3)
    html = (tmp_path / "out" / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 4 and "http://" not in html and "https://" not in html


@pytest.mark.slow
def test_adjust_fixed_values_are_kept(tmp_path: Path) -> None:
    truth = write_synthetic_flight(tmp_path, n_lines=2)
    lever = ",".join(str(v) for v in truth.lever_arm_m)
    assert main(_args(tmp_path, "--lever-arm", lever, "--delay", "0.065")) == 0
    res = json.loads((tmp_path / "out" / "results.json").read_text())
    assert res["lever_arm_m"] == pytest.approx(list(truth.lever_arm_m), abs=1e-12)
    assert res["delay_s"] == pytest.approx(0.065, abs=1e-12)
    assert res["lever_arm_sigma_m"] == [0.0, 0.0, 0.0]


@pytest.mark.slow
def test_adjust_failures_exit_with_clear_messages(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Datum mix (2), missing geoid grid (2), lever arm free without GCP (3, refused), corrupt events (2)."""
    write_synthetic_flight(tmp_path, n_lines=1)
    assert main(_args(tmp_path, "--lever-arm", "0.05,-0.12,-0.08", "--crs", "EPSG:2154")) == 2
    assert "changes datum" in capsys.readouterr().err  # WGS 84 → RGF93 is a 1 m null shift in PROJ
    assert main(_args(tmp_path, "--lever-arm", "0.05,-0.12,-0.08", "--crs", "EPSG:2154+5720",
                      "--datum-tolerance-m", "2")) == 2
    assert "geoid grid" in capsys.readouterr().err
    args = [a for a in _args(tmp_path) if a not in ("--gcp", str(tmp_path / "gcp.csv"))]
    assert main(args) == 3
    assert "refused" in capsys.readouterr().err
    (tmp_path / "events.csv").write_text("image,week,tow\nIMG_0000.JPG,2300,\n")
    assert main(_args(tmp_path, "--lever-arm", "0,0,0")) == 2
    assert "events.csv:2" in capsys.readouterr().err
    assert not (tmp_path / "out" / "results.json").exists()


def test_module_entry_point_runs(tmp_path: Path) -> None:
    """`python -m ground --help` in a fresh interpreter: nothing at import, the adjust and serve commands exist."""
    out = subprocess.run([sys.executable, "-m", "ground", "--help"], capture_output=True, text=True, timeout=60, check=False,
                         cwd=Path(__file__).resolve().parents[2])
    assert out.returncode == 0 and "adjust" in out.stdout and "serve" in out.stdout


def _events_jsonl_from_csv(d: Path, drop: int | None = None) -> list[str]:
    """Rewrite the synthetic events as onboard pairing records (flash marks, counter); returns image names."""
    from onboard.gnsstime import GpsTime
    from onboard.timepulse.marks import ImagePairing, format_line, pairing_record

    rows = [line.split(",") for line in (d / "events.csv").read_text().splitlines()[1:]]
    lines = []
    for i, (_, week, tow) in enumerate(rows):
        if i == drop:
            continue  # the receiver missed this flash: the counter jumps
        t = GpsTime.from_week_tow_s(int(week), float(tow))
        lines.append(format_line(pairing_record(ImagePairing(i, None, None, "no trigger measurement", t, 100 + i,
                                                             20, None))))
    (d / "events.jsonl").write_text("".join(lines))
    return [r[0] for r in rows]


@pytest.mark.slow
def test_events_jsonl_matched_by_exif_capture_times(tmp_path: Path) -> None:
    """Onboard events.jsonl + photos whose EXIF clock is 1 h 12.3 s off GPS, one flash missed: the image without
    a mark is flagged and left out, every other image adjusted (delay now = exposure − flash ≈ 65 ms here)."""
    pil = pytest.importorskip("PIL.Image")
    from onboard.gnsstime import GpsTime

    truth = write_synthetic_flight(tmp_path, n_lines=2)
    names = _events_jsonl_from_csv(tmp_path, drop=5)
    rows = [line.split(",") for line in (tmp_path / "events.csv").read_text().splitlines()[1:]]
    imgs = tmp_path / "images"
    imgs.mkdir()
    for name, (_, week, tow) in zip(names, rows):
        t = GpsTime.from_week_tow_s(int(week), float(tow)).to_gpst_datetime().replace(tzinfo=None)
        t = t.replace(microsecond=0) + dt.timedelta(hours=1, seconds=12.3)
        im = pil.new("RGB", (8, 8))
        exif = im.getexif()
        exif.get_ifd(0x8769)[0x9003] = t.strftime("%Y:%m:%d %H:%M:%S")
        im.save(imgs / name, exif=exif)
    args = ["adjust", "--trajectory", str(tmp_path / "SOL.pos"), "--events", str(tmp_path / "events.jsonl"),
            "--images", str(imgs), "--orientations", str(tmp_path / "poses.csv"), "--gcp", str(tmp_path / "gcp.csv"),
            "--lever-arm", ",".join(map(str, truth.lever_arm_m)), "-o", str(tmp_path / "out")]
    assert main(args) == 0
    res = json.loads((tmp_path / "out" / "results.json").read_text())
    assert res["matching"]["method"] == "capture_time"
    assert res["matching"]["missing_marks"] == [names[5]]
    assert res["matching"]["count_jumps"] == [[104, 106]]
    assert res["n_images"] == truth.n_images - 1
    assert {s["image"] for s in res["skipped"]} == {names[5]}
    assert res["delay_s"] == pytest.approx(truth.delay_s, abs=0.005)


@pytest.mark.slow
def test_gcp_in_projected_crs_and_odm_list_with_relative_file(tmp_path: Path) -> None:
    """GCP ground coordinates given in UTM 30N (--gcp-crs) or as an ODM gcp_list.txt + --gcp-rel give the same
    adjustment as the ECEF CSV."""
    truth = write_synthetic_flight(tmp_path, n_lines=2)
    rows = [line.split(",") for line in (tmp_path / "gcp.csv").read_text().splitlines()]
    ecef = np.array([[float(v) for v in r[5:8]] for r in rows[1:]])
    utm = crsmod.ecef_to_crs(ecef, "EPSG:32630")
    with (tmp_path / "gcp_utm.csv").open("w") as fh:
        fh.write(",".join(rows[0]) + "\n")
        for r, u in zip(rows[1:], utm):
            fh.write(",".join(r[:5] + [f"{v:.4f}" for v in u]) + "\n")
    with (tmp_path / "gcp_list.txt").open("w") as fh:
        fh.write("EPSG:32630\n")
        for r, u in zip(rows[1:], utm):
            label = r[0] if r[1] == "gcp" else f"chk_{r[0]}"
            fh.write(f"{u[0]:.4f} {u[1]:.4f} {u[2]:.4f} 100 200 IMG_0001.JPG {label}\n")
    with (tmp_path / "rel.csv").open("w") as fh:
        fh.write("name,x_rel,y_rel,z_rel\n")
        for r in rows[1:]:
            fh.write(",".join([r[0] if r[1] == "gcp" else f"chk_{r[0]}"] + r[2:5]) + "\n")
    lever = ",".join(map(str, truth.lever_arm_m))
    base = ["adjust", "--trajectory", str(tmp_path / "SOL.pos"), "--events", str(tmp_path / "events.csv"),
            "--orientations", str(tmp_path / "poses.csv"), "--lever-arm", lever, "--lever-arm-sigma", "0.01"]
    outs = {}
    for tag, extra in {"ecef": ["--gcp", str(tmp_path / "gcp.csv")],
                       "utm": ["--gcp", str(tmp_path / "gcp_utm.csv"), "--gcp-crs", "EPSG:32630"],
                       "odm": ["--gcp", str(tmp_path / "gcp_list.txt"), "--gcp-rel", str(tmp_path / "rel.csv")]}.items():
        assert main([*base, *extra, "-o", str(tmp_path / tag)]) == 0, tag
        outs[tag] = json.loads((tmp_path / tag / "results.json").read_text())
    for tag in ("utm", "odm"):
        np.testing.assert_allclose(outs[tag]["translation_m"], outs["ecef"]["translation_m"], atol=2e-3)
        np.testing.assert_allclose(outs[tag]["lever_arm_m"], outs["ecef"]["lever_arm_m"], atol=2e-3)
    assert len(outs["odm"]["checkpoints"]) == 2  # chk_ labels became check points


def _calibration_csv(path: Path, box_shift_m: float = 0.0, noise_m: float = 0.0005, seed: int = 0) -> np.ndarray:
    """Targets of one ground acquisition for a known lever arm; returns that lever arm (camera frame, m)."""
    from ground.io.rotations import rotation_from_axis_angle

    rng = np.random.default_rng(seed)
    cam_targets = rng.uniform(-0.08, 0.08, (5, 3))
    box_targets = rng.uniform(-0.04, 0.04, (4, 3))
    phase_centre = np.array([0.0, 0.0, 0.012])
    r2, t2 = rotation_from_axis_angle([0.1, -0.2, 0.05]), np.array([0.09 + box_shift_m, -0.06, -0.08])
    s1, r1, t1 = 0.5, rotation_from_axis_angle([0.3, 0.1, -0.4]), np.array([1.0, 2.0, 0.5])  # acq → camera

    def to_acq(c: np.ndarray) -> np.ndarray:
        return (c - t1) @ r1 / s1  # inverse of x ↦ s1·R1·x + t1

    lines = ["target,group,x,y,z"]
    for i, c in enumerate(cam_targets):
        lines.append(f"C{i},camera_frame,{c[0]:.6f},{c[1]:.6f},{c[2]:.6f}")
        a = to_acq(c) + rng.normal(0, noise_m, 3)
        lines.append(f"C{i},camera_acq,{a[0]:.6f},{a[1]:.6f},{a[2]:.6f}")
    for i, b in enumerate(box_targets):
        lines.append(f"B{i},box_frame,{b[0]:.6f},{b[1]:.6f},{b[2]:.6f}")
        a = to_acq(r2 @ b + t2) + rng.normal(0, noise_m, 3)
        lines.append(f"B{i},box_acq,{a[0]:.6f},{a[1]:.6f},{a[2]:.6f}")
    lines.append(f"phase_centre,box_frame,{phase_centre[0]},{phase_centre[1]},{phase_centre[2]}")
    path.write_text("\n".join(lines) + "\n")
    return r2 @ phase_centre + t2


@pytest.mark.slow
def test_calibrate_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`python -m ground calibrate` prints the lever arm to pass to adjust; a moved box is flagged (exit 1)."""
    truth = _calibration_csv(tmp_path / "before.csv")
    _calibration_csv(tmp_path / "after.csv", seed=1)
    assert main(["calibrate", str(tmp_path / "before.csv"), "--compare", str(tmp_path / "after.csv"),
                 "-o", str(tmp_path / "cal.json")]) == 0
    out = json.loads((tmp_path / "cal.json").read_text())
    np.testing.assert_allclose(out["calibration"]["lever_arm_m"], truth, atol=0.003)
    assert "--lever-arm " in capsys.readouterr().out and out["comparison"]["stable"]
    _calibration_csv(tmp_path / "moved.csv", box_shift_m=0.02, seed=2)
    assert main(["calibrate", str(tmp_path / "before.csv"), "--compare", str(tmp_path / "moved.csv")]) == 1
    assert "NOT stable" in capsys.readouterr().out
    (tmp_path / "bad.csv").write_text("target,group,x,y,z\nC1,elsewhere,1,2,3\n")
    assert main(["calibrate", str(tmp_path / "bad.csv")]) == 2
    assert "bad.csv:2" in capsys.readouterr().err


@pytest.mark.slow
def test_report_shows_undetermined_parameters(tmp_path: Path) -> None:
    """to_dict() writes null for the σ (and correlations) of an undeterminable parameter: the report says
    "undetermined" instead of failing."""
    from ground.report import render_report

    write_synthetic_flight(tmp_path, n_lines=1)
    assert main(_args(tmp_path, "--lever-arm", "0.05,-0.12,-0.08")) == 0
    res = json.loads((tmp_path / "out" / "results.json").read_text())
    res["delay_sigma_s"] = None
    res["rotation_sigma_rad"][2] = None
    res["correlations"]["matrix"][0][1] = None
    res["residuals"][0]["u_m"] = None
    if res["checkpoints"]:
        res["checkpoints"][0]["sigma_m"] = None
    html = render_report(res)
    assert html.count("undetermined") >= 2 and 'id="parameters"' in html


@pytest.mark.slow
def test_report_says_how_each_parameter_entered_and_what_went_in(tmp_path: Path) -> None:
    """The report's summary names the GCP and check-point counts and the check-point RMS; each parameter row says
    whether it was free, a prior (with its value ± σ) or fixed; a correlation that has its own named warning is
    not repeated as a generic |ρ| line."""
    import re

    write_synthetic_flight(tmp_path, n_lines=3)
    assert main(_args(tmp_path, "--lever-arm", "0.05,-0.12,-0.08", "--lever-arm-sigma", "0.005")) == 0
    res = json.loads((tmp_path / "out" / "results.json").read_text())
    page = (tmp_path / "out" / "report.html").read_text()
    summary = re.search(r'<ul id="summary">(.*?)</ul>', page).group(1)
    assert f"{len(res['gcp_residuals'])} GCP(s) in the adjustment; 2 check point(s)" in summary
    assert f"3D RMS {res['checkpoint_rms_m']['3d'] * 100:.1f} cm" in summary
    rows = re.findall(r"<tr><td>(lever arm O_x|shutter delay t_d)</td>.*?<td>([^<]*)</td></tr>", page)
    assert dict(rows) == {"lever arm O_x": "estimated, prior 50.0 ± 5.0 mm", "shutter delay t_d": "estimated (free)"}
    assert 'id="gcps"' in page
    if any(w.startswith("vertical lever arm O_z and vertical translation T_u") for w in res["warnings"]):
        assert not any(w.startswith("|ρ(T_u, O_z)|") for w in res["warnings"])
    assert main(_args(tmp_path, "--lever-arm", "0.05,-0.12,-0.08", "--delay", "0.065")) == 0
    page = (tmp_path / "out" / "report.html").read_text()
    assert re.search(r"<tr><td>lever arm O_y</td>.*?<td>fixed \(given\)</td></tr>", page)


@pytest.mark.parametrize(
    ("command", "phrases"),
    [
        ("adjust", ("a value alone is fixed", "value with its σ is a prior", "exit codes", "x right, y down",
                    "(default: EPSG:4979")),
        ("serve", ("Authorization: Bearer", "(default: 8600)", "(default: 16.0 MiB)", "/openapi.json")),
        ("calibrate", ("camera_frame", "phase_centre", "prints the --lever-arm", "Exit codes")),
    ],
)
def test_help_explains_the_rules_units_and_defaults(
    command: str, phrases: tuple[str, ...], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as stop:
        main([command, "--help"])
    assert stop.value.code == 0
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    for phrase in phrases:
        assert phrase in text, phrase
