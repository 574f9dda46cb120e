"""``station bench kinematics``: poses per second for the exact error model.

Measures, as medians over repeats on one core (numpy's elementwise kernels and
its stacked 3x3 products are single-threaded):

* the vectorised model: exact E (Eq. 12), its six components (Eq. 13) and the
  detection point's displacement, from the error motions' values at the poses
  (the goal's "E plus extraction"); and the same with the error-motion tables and
  effects evaluated too;
* the straightforward per-pose loop of 4x4 matrices (``kinematics.reference``),
  on fewer poses, as the baseline; and the ratio;
* inverse compensation: targets per second, iterations, worst residual.
"""

from __future__ import annotations

import statistics
import time

import numpy as np
import typer

from station.cli.common import out_console, print_json


def run(poses: int = 1_000_000, loop_poses: int = 2_000, repeats: int = 5, seed: int = 0) -> dict:
    from station.kinematics.inverse import compensate
    from station.kinematics.model import load_model
    from station.kinematics.reference import error_matrix_loop

    model = load_model()
    rng = np.random.default_rng(seed)
    z = rng.uniform(*model.z_travel_mm, poses)
    c = rng.uniform(0.0, 360.0, poses)
    model.errors(z[:1000], c[:1000])  # warm-up

    vec_rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        model.errors(z, c)
        vec_rates.append(poses / (time.perf_counter() - t0))
    # E plus extraction alone, the error motions' values given (what the goal names)
    motions = model.motion_values_si(z, c)
    core_rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        model.errors(z, c, motions_si=motions)
        core_rates.append(poses / (time.perf_counter() - t0))
    loop_rates = []
    for _ in range(max(1, repeats // 2)):
        t0 = time.perf_counter()
        error_matrix_loop(model, z[:loop_poses], c[:loop_poses])
        loop_rates.append(loop_poses / (time.perf_counter() - t0))
    # agreement of the two on the poses both computed: the speed is not bought with accuracy
    agree = float(np.max(np.abs(model.error_matrix(z[:loop_poses], c[:loop_poses]) - error_matrix_loop(model, z[:loop_poses], c[:loop_poses]))))

    n_inv = min(poses, 100_000)
    axial = rng.uniform(model.z_travel_mm[0] + 1, model.z_travel_mm[1] - 1, n_inv)
    angle = rng.uniform(-180.0, 180.0, n_inv)
    inv_rates = []
    sol = None
    for _ in range(max(1, repeats // 2)):
        t0 = time.perf_counter()
        sol = compensate(model, axial, angle)
        inv_rates.append(n_inv / (time.perf_counter() - t0))
    assert sol is not None
    vec = statistics.median(vec_rates)
    loop = statistics.median(loop_rates)
    return {
        "poses": poses,
        "repeats": repeats,
        "vectorised_poses_per_s": statistics.median(core_rates),
        "vectorised_poses_per_s_all": core_rates,
        "with_curve_evaluation_poses_per_s": vec,
        "loop_poses": loop_poses,
        "loop_poses_per_s": loop,
        # like for like: the loop evaluates the curves too
        "speedup_vs_loop": vec / loop,
        "max_abs_difference_vectorised_vs_loop": agree,
        "goal_poses_per_s": 1_000_000,
        "inverse_targets": n_inv,
        "inverse_targets_per_s": statistics.median(inv_rates),
        "inverse_iterations": sol.iterations,
        "inverse_converged_fraction": float(np.mean(sol.converged)),
        "inverse_worst_axial_residual_nm": float(np.max(np.abs(sol.axial_error_mm)) * 1e6),
        "inverse_worst_angle_residual_arcsec": float(np.max(np.abs(sol.angle_error_deg)) * 3600),
    }


def register(bench_app: typer.Typer) -> None:
    @bench_app.command("kinematics")
    def kinematics(
        poses: int = typer.Option(1_000_000, help="poses for the vectorised model"),
        loop_poses: int = typer.Option(2_000, help="poses for the per-pose baseline"),
        repeats: int = typer.Option(5, help="repeats; medians are reported"),
        json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
    ) -> None:
        """Poses per second for exact E plus extraction, against a per-pose loop."""
        with out_console.status("timing the error model..."):
            result = run(poses, loop_poses, repeats)
        if json:
            print_json(result)
            return
        from rich.table import Table

        t = Table(title="Kinematics benchmark (medians, one core)")
        t.add_column("what")
        t.add_column("figure", justify="right")
        t.add_row("vectorised E + extraction", f"{result['vectorised_poses_per_s']:,.0f} poses/s")
        t.add_row("  with the error-motion curves evaluated", f"{result['with_curve_evaluation_poses_per_s']:,.0f} poses/s")
        t.add_row("per-pose 4x4 loop", f"{result['loop_poses_per_s']:,.0f} poses/s")
        t.add_row("speed-up", f"{result['speedup_vs_loop']:,.0f} x")
        t.add_row("max |E_vec - E_loop|", f"{result['max_abs_difference_vectorised_vs_loop']:.1e}")
        t.add_row("inverse compensation", f"{result['inverse_targets_per_s']:,.0f} targets/s")
        t.add_row("inverse worst residual", f"{result['inverse_worst_axial_residual_nm']:.2e} nm, {result['inverse_worst_angle_residual_arcsec']:.2e} arcsec")
        out_console.print(t)
