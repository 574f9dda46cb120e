"""``station model ...``: the geometric error model from the command line."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from station.cli.common import fail, out_console, print_json

model_app = typer.Typer(help="The MBS error model: topology, errors at poses, budget, inverse compensation.", no_args_is_help=True)

ModelOpt = typer.Option(None, "--model", help="station model TOML (default: the built-in default station)")


def _load(path: Optional[Path]):
    from station.kinematics.model import ModelConfigError, load_model

    try:
        return load_model(path)
    except ModelConfigError as exc:
        fail(str(exc))


@model_app.command("topology")
def topology(json: bool = typer.Option(False, "--json")) -> None:
    """The lower-order body array (Table 1, corrected) and the two chains."""
    from station.kinematics.topology import load_topology

    topo = load_topology()
    rows = topo.lower_order_array()
    names = [b.name for b in topo.bodies]
    if json:
        print_json({"bodies": names, "L": rows, "tool_chain": [names[j] for j in topo.tool_chain],
                    "workpiece_chain": [names[j] for j in topo.workpiece_chain]})
        return
    t = Table(title="Lower-order body array")
    t.add_column("")
    for j, n in enumerate(names):
        t.add_column(f"{j} {n}", justify="right")
    for k, row in enumerate(rows):
        t.add_row(f"L^{k}", *["-" if v is None else str(v) for v in row])
    out_console.print(t)
    out_console.print("detecting chain: R -> " + " -> ".join(names[j] for j in topo.tool_chain))
    out_console.print("workpiece chain: R -> " + " -> ".join(names[j] for j in topo.workpiece_chain))


@model_app.command("errors")
def errors(
    z: list[float] = typer.Option(..., "--z", help="slide position(s), mm"),
    c: list[float] = typer.Option([0.0], "--c", help="table angle(s), deg"),
    model: Optional[Path] = ModelOpt,
    json: bool = typer.Option(False, "--json"),
) -> None:
    """E's six components (Eq. 13) and the detection point's displacement at poses."""
    m = _load(model)
    zz, cc = np.broadcast_arrays(np.asarray(z, float), np.asarray(c, float))
    e = m.errors(zz, cc)
    ax, an, _ = m.part_coordinates(e.actual_point_mm)
    rows = [
        {"z_mm": float(zz[i]), "c_deg": float(cc[i]),
         "dx_um": e.d_mm[i, 0] * 1e3, "dy_um": e.d_mm[i, 1] * 1e3, "dz_um": e.d_mm[i, 2] * 1e3,
         "theta_x_arcsec": e.theta_arcsec[i, 0], "theta_y_arcsec": e.theta_arcsec[i, 1], "theta_z_arcsec": e.theta_arcsec[i, 2],
         "point_displacement_um": e.displacement_um[i].tolist(),
         "axial_error_um": (ax[i] - zz[i]) * 1e3, "angle_error_arcsec": ((an[i] - cc[i] + 180) % 360 - 180) * 3600}
        for i in range(zz.size)
    ]
    if json:
        print_json({"poses": rows})
        return
    t = Table(title="Error of the detection point (exact E, Eq. 12-13)")
    for col in ("z mm", "C deg", "dx um", "dy um", "dz um", "θx ″", "θy ″", "θz ″", "axial um", "angle ″"):
        t.add_column(col, justify="right")
    for r in rows:
        t.add_row(*(f"{v:.3f}" for v in (r["z_mm"], r["c_deg"], r["dx_um"], r["dy_um"], r["dz_um"], r["theta_x_arcsec"],
                                         r["theta_y_arcsec"], r["theta_z_arcsec"], r["axial_error_um"], r["angle_error_arcsec"])))
    out_console.print(t)


@model_app.command("budget")
def budget(
    model: Optional[Path] = ModelOpt,
    json: bool = typer.Option(False, "--json"),
    plot: Optional[Path] = typer.Option(None, "--plot", help="bar chart PNG of the budget"),
    top: int = typer.Option(15, help="rows to show"),
) -> None:
    """Which error matters where: each parameter's largest first-order contribution."""
    from station.kinematics.budget import error_budget

    m = _load(model)
    zg, cg = np.meshgrid(np.linspace(*m.z_travel_mm, 31), np.arange(0.0, 360.0, 10.0))
    rows = error_budget(m, zg.ravel(), cg.ravel())
    if json:
        print_json({"model": m.name, "rows": [asdict(r) for r in rows]})
    else:
        t = Table(title=f"Error budget of {m.name} (first order, over the travel and the revolution)")
        for col in ("parameter", "axial um", "tangential um", "angle ″", "radial um", "worst at z mm", "C deg"):
            t.add_column(col, justify="right")
        for r in rows[:top]:
            t.add_row(r.parameter, f"{r.max_axial_um:.3f}", f"{r.max_tangential_um:.3f}", f"{r.max_angle_arcsec:.2f}",
                      f"{r.max_radial_um:.3f}", f"{r.worst_z_mm:.1f}", f"{r.worst_c_deg:.0f}")
        out_console.print(t)
    if plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        shown = rows[:top]
        fig, ax = plt.subplots(figsize=(9, 5))
        y = np.arange(len(shown))
        ax.barh(y - 0.2, [r.max_axial_um for r in shown], 0.4, label="axial (um)", color="0.3")
        ax.barh(y + 0.2, [r.max_tangential_um for r in shown], 0.4, label="tangential (um)", color="0.7")
        ax.set_yticks(y, [r.parameter for r in shown])
        ax.invert_yaxis()
        ax.set_xlabel("largest first-order contribution over the travel, um")
        ax.set_title(f"Error budget: {m.name}")
        ax.legend()
        fig.tight_layout()
        fig.savefig(plot, dpi=110)
        plt.close(fig)


@model_app.command("compensate")
def compensate_cmd(
    axial: list[float] = typer.Option(..., "--axial", help="target axial position(s) on the part, mm"),
    angle: list[float] = typer.Option([0.0], "--angle", help="target angle(s) on the part, deg"),
    model: Optional[Path] = ModelOpt,
    json: bool = typer.Option(False, "--json"),
) -> None:
    """Commanded (z, C) that puts the detection point on each target (Newton, exact model)."""
    from station.kinematics.inverse import compensate

    m = _load(model)
    a, g = np.broadcast_arrays(np.asarray(axial, float), np.asarray(angle, float))
    sol = compensate(m, a, g)
    rows = [{"axial_mm": float(a[i]), "angle_deg": float(g[i]), "z_cmd_mm": float(sol.z_mm[i]), "c_cmd_deg": float(sol.c_deg[i]),
             "dz_um": float(sol.dz_mm[i] * 1e3), "dc_arcsec": float(sol.dc_deg[i] * 3600),
             "residual_nm": float(sol.axial_error_mm[i] * 1e6), "residual_arcsec": float(sol.angle_error_deg[i] * 3600),
             "converged": bool(sol.converged[i])} for i in range(a.size)]
    if json:
        print_json({"iterations": sol.iterations, "targets": rows})
        return
    t = Table(title=f"Inverse compensation ({sol.iterations} Newton iterations)")
    for col in ("axial mm", "angle deg", "z cmd mm", "C cmd deg", "dz um", "dC ″", "residual nm", "residual ″"):
        t.add_column(col, justify="right")
    for r in rows:
        t.add_row(f"{r['axial_mm']:.4f}", f"{r['angle_deg']:.4f}", f"{r['z_cmd_mm']:.6f}", f"{r['c_cmd_deg']:.6f}",
                  f"{r['dz_um']:.3f}", f"{r['dc_arcsec']:.2f}", f"{r['residual_nm']:.2e}", f"{r['residual_arcsec']:.1e}")
    out_console.print(t)
    if not sol.converged.all():
        fail("some targets did not converge", code=1)


@model_app.command("proposals")
def proposals_cmd(
    data: Path = typer.Option(Path("var"), "--data", help="the station's data folder"),
    json: bool = typer.Option(False, "--json"),
) -> None:
    """Model proposals the station made from its own evidence (docs/monitor.md)."""
    from station.monitor.proposals import ProposalBook

    book = ProposalBook(data)
    items = book.list()
    if json:
        print_json({"proposals": [p.to_json() for p in items],
                    "approved_changes": [c.__dict__ for c in book.approved_changes()]})
        return
    if not items:
        out_console.print("no model proposals")
    for p in items:
        out_console.print(f"[bold]{p.id}[/] {p.state} ({p.created_at}) on {p.base_version}: {p.reason}")
        for c in p.changes:
            out_console.print(f"  {c.term} {c.delta:+.3f}: {c.why}")
        out_console.print("  expected change: " + ", ".join(f"{h} {v:+.2f} um" for h, v in p.expected_change_um.items()))
        if p.decided_by:
            out_console.print(f"  {p.state} by {p.decided_by} at {p.decided_at}" + (f": {p.decision_note}" if p.decision_note else ""))


def _decide(pid: str, approve: bool, who: str, note: str, data: Path) -> None:
    from station.monitor.proposals import ProposalBook, ProposalError
    from station.store import Store
    from station.store.errors import StoreError

    try:
        p = ProposalBook(data).decide(pid, approve, who, note)
    except ProposalError as exc:
        fail(str(exc), 2)
    try:
        with Store(data_dir=data) as store:  # a reader: the audit entry, not the station's ownership
            store.log_event("approval" if approve else "rejection",
                            f"model proposal {p.id} {'approved' if approve else 'rejected'} by {who} (command line)"
                            + (f": {note}" if note else ""))
    except StoreError as exc:
        fail(f"decision recorded in {data}/models but not in the event log: {exc}", 2)
    out_console.print(f"proposal {p.id} {p.state}" + ("; the station uses it from its next start" if approve else ""))


@model_app.command("approve")
def approve_cmd(proposal: str = typer.Argument(...), who: str = typer.Option(..., "--who", help="the engineer"),
                note: str = typer.Option("", "--note"), data: Path = typer.Option(Path("var"), "--data")) -> None:
    """Approve a model proposal (a running station takes it over REST at once; from here, at its next start)."""
    _decide(proposal, True, who, note, data)


@model_app.command("reject")
def reject_cmd(proposal: str = typer.Argument(...), who: str = typer.Option(..., "--who", help="the engineer"),
               note: str = typer.Option("", "--note"), data: Path = typer.Option(Path("var"), "--data")) -> None:
    """Reject a model proposal."""
    _decide(proposal, False, who, note, data)


def register(app: typer.Typer) -> None:
    app.add_typer(model_app, name="model")
