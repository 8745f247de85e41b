"""Pure numpy/scipy core of the final adjustment (similarity, lever arm, shutter delay, GCPs).

Entry points (nothing is imported here; import the modules):
- `ground.adjust.solve.build_problem(poses, events, trajectory, control, origin_ecef_m)` → `AdjustmentProblem`
  (matches images and events by name, Hermite-interpolates the antenna, lists what it skipped and why);
- `ground.adjust.solve.adjust(problem, AdjustmentOptions(...))` → `AdjustmentResult` (`.to_dict()` for JSON),
  raising `ground.adjust.model.AdjustmentRefused` with a clear message when the problem is not solvable as posed;
- `ground.adjust.calibration.calibrate_lever_arm(CalibrationInput)` / `compare_calibrations(a, b)`: the ground
  (pseudo-materialization) lever-arm calibration; its CSV is read by `ground.io.calibration_csv`;
- `ground.adjust.interpolate.interpolate_antenna`, `ground.adjust.relative`, `ground.adjust.similarity`;
- `ground.adjust.simulate`: synthetic blocks for tests and benchmarks only.
"""
