"""`precland-eval --report DIR`: what the evaluation did, as Markdown and PNG plots (matplotlib).

- `report.md`: the settings, the seeds every row flew, each scenario's sensors, faults and wind,
  the table (both landing paths), and the plots;
- `touchdown.png`: where each trial touched down (hollow grey: aborted, where it held aloft), one
  panel per scenario and landing path, the 5 cm circle of the charging contacts drawn;
- `error_vs_time.png`: one trial followed through time (the first seed of the traced scenario, each
  path that flew it): the vehicle's true horizontal distance from the pad, the landing system's
  own estimate's error (the agent's filter, or the autopilot's PLND estimator while it has the
  target), and the height.

Rewritten as each row finishes, so a run cut short keeps what it measured.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

CONTACTS_M = 0.05


@dataclass
class Trace:
    """One trial through time: (t s, true horizontal distance m, height m, estimate error m or
    NaN when the landing system has no estimate), sampled every `every` steps."""

    every: int = 5
    rows: list[tuple[float, float, float, float]] = field(default_factory=list)
    _k: int = 0

    def record(
        self,
        t: float,
        vehicle_ne: tuple[float, float],
        height: float,
        estimate_rel_ne: tuple[float, float] | None,
    ) -> None:
        """A step: the vehicle's true position (pad at the origin), its height above the pad,
        and the landing system's estimate of pad minus vehicle (None: none)."""
        self._k += 1
        if (self._k - 1) % self.every:
            return
        n, e = vehicle_ne
        err = math.nan
        if estimate_rel_ne is not None:
            err = math.hypot(estimate_rel_ne[0] + n, estimate_rel_ne[1] + e)
        self.rows.append((t, math.hypot(n, e), height, err))


def _plot_touchdowns(folder: Path, touchdowns: dict[str, list[Any]]) -> None:
    import matplotlib.pyplot as plt

    n = len(touchdowns)
    cols = min(n, 4)
    rows = max(1, math.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.2 * rows), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax, (label, trials) in zip(axes.flat, touchdowns.items(), strict=False):
        cm = np.array([[100 * tr.touchdown[1], 100 * tr.touchdown[0]] for tr in trials])
        down = np.array([tr.landed for tr in trials], dtype=bool)
        note = ""
        # scaled to the touchdowns (metres away, a trial held aloft would hide them): one held
        # farther is drawn at the edge, in its direction
        lim = max(10.0, float(np.abs(cm[down] if down.any() else cm).max()) * 1.2)
        ax.add_patch(plt.Circle((0, 0), 100 * CONTACTS_M, fill=False, color="green"))
        ax.scatter(cm[down, 0], cm[down, 1], s=14, color="tab:red")
        if not down.all():  # aborted: where it held at the safe height, not a touchdown
            aloft = cm[~down]
            far = np.abs(aloft).max(axis=1, keepdims=True)
            edge = aloft * np.minimum(1.0, 0.95 * lim / np.maximum(far, 1e-9))
            ax.scatter(edge[:, 0], edge[:, 1], s=16, facecolors="none", edgecolors="grey")
            off = np.hypot(aloft[:, 0], aloft[:, 1]) / 100
            note = (
                f"\n○ {len(aloft)} held aloft ({off.min():.1f}–{off.max():.1f} m off), not landed"
            )
        ax.plot(0, 0, "k+")
        ax.set(xlim=(-lim, lim), ylim=(-lim, lim), aspect="equal", title=label)
        ax.set_xlabel("east, cm" + note, fontsize=8)
        ax.set_ylabel("north, cm", fontsize=8)
        ax.title.set_fontsize(8)
    title = (
        f"touchdowns (●) around the pad's centre (+); green: the charging contacts, "
        f"{100 * CONTACTS_M:g} cm"
    )  # wrapped to the figure's width (9 pt: about 40 characters to a 3.2-inch panel)
    fig.suptitle(textwrap.fill(title, width=40 * cols), fontsize=9)
    fig.tight_layout()
    fig.savefig(folder / "touchdown.png", dpi=90)
    plt.close(fig)


def _plot_traces(folder: Path, traces: dict[str, Trace], title: str) -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(traces), 1, figsize=(8, 3.4 * len(traces)), squeeze=False)
    for ax, (label, trace) in zip(axes[:, 0], traces.items(), strict=True):
        a = np.array(trace.rows)
        ax.semilogy(
            a[:, 0], 100 * np.maximum(a[:, 1], 1e-3), color="tab:red", label="truth: off the pad"
        )
        ax.semilogy(a[:, 0], 100 * np.maximum(a[:, 3], 1e-3), color="tab:blue", lw=0.8,
                    label="its estimate's error")  # fmt: skip
        ax.axhline(100 * CONTACTS_M, color="green", ls="--", lw=0.8, label="contacts 5 cm")
        ax.set(ylim=(0.1, 500), xlabel="time, s", ylabel="horizontal, cm", title=label)
        ax.title.set_fontsize(9)
        ax.legend(loc="upper right", fontsize=7)
        height = ax.twinx()
        height.plot(a[:, 0], a[:, 2], color="grey", lw=0.8)
        height.set_ylabel("height, m", color="grey")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(folder / "error_vs_time.png", dpi=90)
    plt.close(fig)


def _figure(value: float | None) -> str:
    return "—" if value is None else f"{value}"


def _scenario_line(name: str, sc: Any, gnss: str | None = None) -> str:
    faults = ", ".join(
        f"{src}: " + " ".join(f"{k}={v}" for k, v in f.model_dump().items() if v)
        for src, f in sc.faults.items()
    )
    return (
        f"| {name} | {' + '.join(sc.sensors) or 'none'} | {faults or '—'} "
        f"| {'yes' if sc.cautious else ''} | {sc.start_height:g} | {sc.wind:g} | {sc.gust:g} "
        f"| {gnss or sc.gnss} |"
    )


def write_report(
    folder: Path,
    results: dict,
    touchdowns: dict[str, list[Any]],
    scenarios: dict[str, Any],
    traces: dict[str, Trace] | None = None,
) -> None:
    """report.md, touchdown.png and (with `traces`) error_vs_time.png in `folder`."""
    import matplotlib

    matplotlib.use("Agg")
    folder.mkdir(parents=True, exist_ok=True)
    _plot_touchdowns(folder, touchdowns)
    seeds = results["seeds"]
    if traces:
        _plot_traces(folder, traces, f"one trial through time: seed {seeds[0]}")
    n = results["trials"]
    lines = [
        "# precland-eval report",
        "",
        f"Command: `{results['command']}`. {n} trials per row, camera {results['camera_hz']} Hz,"
        f" vehicle model {results['vehicle_model']}, the agent's filter predicted by "
        f"{results['motion']}. Landing error in cm (true horizontal distance from the pad centre"
        " at touchdown).",
        "",
        f"**Seeds**: every row flies the same {n} seeds, {seeds[0]}–{seeds[-1]} (trial *i* flies "
        f"seed {seeds[0]} + *i*; `--seed {results['seed']}`). A seed fixes the start (2 m off in "
        "a random direction, random yaw), the GNSS error, the survey error, the wind's direction, "
        "the gust's moment and direction, the turbulence and every sensor's noise, so a row can "
        "be flown again exactly. Mean and max are over the trials that landed; a trial that "
        "searched in vain without an RTK fixed GNSS climbs and holds (`aborted-climb`).",
        "",
        "| scenario | path | landed | mean | max | heading ° | time s | thesis | landing paths |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for key, path in (("scenarios", "agent steers"), ("autopilot", "autopilot PLND")):
        for name, row in results[key].items():
            lines.append(
                f"| {name} | {path} | {row['landed']}/{n} | {_figure(row['mean_cm'])} "
                f"| {_figure(row['max_cm'])} | {_figure(row['heading_deg'])} | {row['time_s']} "
                f"| {row['published'] or ''} "
                f"| {', '.join(f'{k} {v}' for k, v in row.get('paths', {}).items())} |"
            )
    flown = [*dict.fromkeys([*results["scenarios"], *results["autopilot"]])]
    lines += [
        "",
        "Scenarios (wind: the mean 20 ft above the ground, m/s, with shear and Dryden turbulence"
        " at the vehicle, and one 1-cosine gust of the given peak; `bench/precland_wind.py`):",
        "",
        "GNSS: the fix type of the autopilot's GNSS on both paths (`bench/precland_gnss.py`: "
        "rtk_fixed 0.85 cm per axis, 0.6 cm of it over 1 s and 0.6 cm over 100 s; rtk_float "
        "0.25 m over 60 s; 3d 0.5 m over 120 s), reported to the agent's filter as GPS_RAW_INT's "
        "fix_type; on the autopilot path the simulated autopilot's EKF position drifts with it "
        "(the same draws per seed). The surveyed pad is off by up to 2 cm with RTK, 1 m on a 3D fix.",
        "",
        "| scenario | sensors | faults | cautious | start m | wind | gust | GNSS |",
        "|---|---|---|---|---|---|---|---|",
        *(_scenario_line(name, scenarios[name], results.get("gnss")) for name in flown),
        "",
        "![touchdown per scenario](touchdown.png)",
        "",
    ]
    if traces:
        lines += [
            f"One trial through time (seed {seeds[0]}): the true distance from the pad, the "
            "error of the landing system's own estimate (the agent's filter; the autopilot's "
            "PLND estimator while it has the target) and the height.",
            "",
            "![error vs time](error_vs_time.png)",
            "",
        ]
    (folder / "report.md").write_text("\n".join(lines))
