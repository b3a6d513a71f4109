"""What a diagnosis writes: the extended model file, figures, REPORT.md, report.json, a terminal summary."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from phfdi.faults import EXTENDED_MARK
from phfdi.loop import build_parts
from phfdi.scenario import load_scenario
from phfdi_base.errors import UserError
from phfdi_base.outputs import write_text
from phfdi_base.signals import label

from .extend import load_model_file, write_model
from .figures import plot_fit, plot_ranking, plot_scalogram
from .model import Evaluator
from .pipeline import Diagnosis
from .report import fmt_num, fmt_params, to_json, verdict_line

#: relative agreement required between the written model and what the diagnosis scored
REPRODUCE_RTOL = 1e-5


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(text).stem)[:60]


def write_extended(d: Diagnosis, out_dir: Path, model: str) -> Path | None:
    """Write the extended model and check that, loaded back, it predicts what was scored."""
    if d.extended_raw is None:
        return None
    rep = d.report
    name = f"{Path(model).stem}{EXTENDED_MARK}-{rep['cause'].replace('+', '-')}"  # phfdi.faults.base_scenario
    header = (f"written by phfdi diagnose: the nominal model {model!r} plus the fitted extension\n"
              f"cause: {rep['cause']} ({rep['family']}); {fmt_params(rep['parameters'], rep.get('confidence_intervals'))}\n"
              f"verdict: {rep['verdict']}; held-out NRMSE {fmt_num(rep['nrmse_nominal'])} -> "
              f"{fmt_num(rep['nrmse_extended'])} ({fmt_num(rep['gain_percent'], '+.1f')} %)\n"
              f"run it: phfdi simulate --scenario {out_dir / 'extended_model.yaml'}")
    path = write_model(out_dir / "extended_model.yaml", model, d.extended_raw, header, name)
    _check_reproduces(d, path)
    rep["extended_model"] = str(path)
    rep["extended_model_closed_loop"] = _check_closed_loop(path)
    return path


def _check_closed_loop(path: Path) -> dict:
    """Can `phfdi simulate --scenario` run the file? (An extended plant may not reach the scenario's setpoints.)"""

    try:
        build_parts(load_scenario(str(path)))
    except UserError as exc:
        return {"ok": False, "message": f"phfdi simulate cannot run it as written: {exc} (the extended plant; "
                                        f"give reachable setpoints with --set)"}
    return {"ok": True, "message": f"phfdi simulate --scenario {path} runs it"}


def _check_reproduces(d: Diagnosis, path: Path) -> None:
    raw = load_model_file(path)
    worst = 0.0
    for i, rec in enumerate(d.records):
        if d.extended_record_raws and d.extended_record_raws[i] is not d.extended_raw \
                and d.extended_record_raws[i] != d.extended_raw:
            continue  # a record of another group: its per-group parameters are in the report, not this file
        ev = Evaluator(rec, raw, d.report.get("initial", "steady"))
        pred = ev.predict(raw, d.extended_starts[i])
        for o, y in d.extended[i].outputs.items():
            scale = float(np.std(rec.outputs[o])) or 1.0
            worst = max(worst, float(np.max(np.abs(pred.outputs[o] - y))) / scale)
    d.report["extended_model_check"] = {"max_relative_difference": worst, "ok": worst <= REPRODUCE_RTOL}
    if worst > REPRODUCE_RTOL:
        raise UserError(f"internal check failed: the written model {path} does not reproduce the fitted "
                        f"predictions (max difference {worst:.2g} of the output's spread)")


def write_figures(d: Diagnosis, out_dir: Path) -> list[str]:
    rep = d.report
    files = []
    if not d.nominal:
        return files
    for i, rec in enumerate(d.records):
        ext = d.extended[i] if d.extended is not None else None
        files.append(str(plot_fit(rec, d.nominal[i], ext, d.val[i], out_dir / f"fit_{i + 1}_{_slug(rec.name)}.png",
                                  rep["cause"])))
        for o in rec.outputs:
            res = rec.outputs[o] - d.nominal[i].outputs[o]
            files.append(str(plot_scalogram(rec, res, o, out_dir / f"scalogram_{i + 1}_{_slug(rec.name)}_{o}.png",
                                            f"{rec.name}: residual of the nominal model's "
                                            f"{label(o).rsplit(' (', 1)[0]} and its wavelet scalogram")))
    if rep["ranking"]:
        files.append(str(plot_ranking(rep, out_dir / "ranking.png")))
    rep["figures"] = files
    return files


def write_structure(d: Diagnosis, out_dir: Path, model: str) -> Path | None:
    """The structure search's final model as a scenario file (the first fitted group's values)."""
    search = d.report.get("structure_search")
    if d.structure is None or search is None:
        return None
    final = search["path"][[s["accepted"] for s in search["path"]].index(False) - 1] \
        if not all(s["accepted"] for s in search["path"]) else search["path"][-1]
    header = (f"written by phfdi diagnose --structure: the nominal model {model!r} plus "
              f"{' + '.join(search['chosen'])}\n"
              f"{fmt_params(final['parameters'], final.get('confidence_intervals'))}\n"
              f"held-out NRMSE {fmt_num(search['nrmse_nominal'])} -> {fmt_num(search['nrmse_final'])}\n"
              f"run it: phfdi simulate --scenario {out_dir / 'structure_model.yaml'}")
    path = write_model(out_dir / "structure_model.yaml", model, d.structure.raw, header,
                       f"{Path(model).stem}-structure")
    search["model_file"] = str(path)
    return path


def write_all(d: Diagnosis, out_dir: str | Path, model: str, command: str = "") -> dict:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_extended(d, out, model)
    write_structure(d, out, model)
    write_figures(d, out)
    write_text(out / "report.json", to_json(d.report), overwrite=True)
    write_text(out / "REPORT.md", report_markdown(d.report, command), overwrite=True)
    d.report["report_dir"] = str(out)
    return d.report


# ---- text ---------------------------------------------------------------------------
def _misfit_lines(m: dict) -> list[str]:
    unit = {"ph_measured": "pH", "level_measured_cm": "cm"}[m["output"]]
    lines = [f"- **{m['record']} / {m['output']}**: NRMSE {m['nrmse']:.4f} (fit {m['fit_percent']:.1f} %), "
             f"RMSE {m['rmse']:.4g} {unit} = {m['shape']['rmse_over_noise']:.2f} x the noise floor "
             f"({m['shape']['noise_floor']:.3g} {unit})"]
    for f in m["shape"]["findings"]:
        lines.append(f"  - {f['text']}")
    scales = sorted(m["scales"], key=lambda s: -s["share"])[:3]
    lines.append("  - scales: " + "; ".join(
        f"{100 * s['share']:.0f} % at periods {s['period_s'][0]:.3g}-"
        f"{'inf' if s['period_s'][1] is None or not math.isfinite(s['period_s'][1]) else format(s['period_s'][1], '.3g')} s"
        for s in scales))
    times = sorted(m["time"], key=lambda s: -s["share"])[:3]
    lines.append("  - time: " + "; ".join(f"{100 * s['share']:.0f} % in {s['start_s']:.0f}-{s['end_s']:.0f} s"
                                          for s in times))
    w = m["whiteness"]
    lines.append(f"  - whiteness (Ljung-Box, {w['lags']} lags): Q = {w['q']:.3g}, p = {w['p_value']:.2g} "
                 f"({'white' if w['white'] else 'not white'})")
    corr = ", ".join(f"{k} {v['max_abs_corr']:.2f} at {v['lag_s']:.3g} s{' (significant)' if v['significant'] else ''}"
                     for k, v in m["input_correlation"].items())
    lines.append(f"  - correlation with input changes (99 % bound {next(iter(m['input_correlation'].values()))['bound']:.3f}): "
                 f"{corr}" if m["input_correlation"] else "  - no inputs")
    return lines


def _candidate_table(entries: list[dict]) -> list[str]:
    rows = ["| rank | cause | family | held-out error / noise | held-out NRMSE | gain % | p | BIC | parameters (95 % interval) |",
            "| ---: | --- | --- | ---: | ---: | ---: | ---: | ---: | --- |"]
    for i, r in enumerate(entries):
        params = fmt_params(r["parameters"], r.get("confidence_intervals"))
        if r.get("fixed"):
            params += " (" + ", ".join(f"{k}: {v}" for k, v in r["fixed"].items()) + ")"
        rows.append(f"| {i + 1} | {r['cause']} | {r['family']} | {r['validation_rmse_over_noise']:.3g} | "
                    f"{fmt_num(r['nrmse_validation'], '.4f')} | {r['gain_percent']:+.1f} | {r['p_value_vs_nominal']:.2g} | "
                    f"{fmt_num(r['bic'], '.0f')} | {params} |")
    return rows


def report_markdown(rep: dict, command: str = "") -> str:
    lines = [f"# Model diagnosis: {rep['model']}", ""]
    if command:
        lines += ["```", command, "```", ""]
    lines += [f"**{verdict_line(rep)}**", "", rep["reason"], ""]
    lines += ["## Data", "", "| record | samples | sample time (s) | duration (s) | inputs | outputs |",
              "| --- | ---: | ---: | ---: | --- | --- |"]
    for r in rep["data"]:
        lines.append(f"| {r['name']} | {r['samples']} | {r['sample_time_s']:.4g} | {r['duration_s']:.1f} | "
                     f"{', '.join(r['inputs'])} | {', '.join(r['outputs'])} |")
    lines.append("")
    lines += [f"- {n}" for n in rep["notes"]] + [""]
    lines += ["Noise floor (finest-scale wavelet MAD of each measurement): " + ", ".join(
        f"{k} {v:.3g}" for k, v in rep["noise_floor"].items()), ""]
    if rep["verdict"] == "not_identifiable":
        return "\n".join(lines) + "\n"
    lines += ["## What the nominal model gets wrong", ""]
    for m in rep["misfit"]:
        lines += _misfit_lines(m)
    lines += ["", "Figures: " + ", ".join(f"`{Path(f).name}`" for f in rep.get("figures", [])
                                          if "fit_" in f or "scalogram_" in f), ""]
    th = rep["thresholds"]
    lines += ["## Candidates", "", f"Held-out error in multiples of the noise floor (1 = a perfect model); a candidate "
              f"counts when it lowers the held-out error significantly (p < {th['alpha']}) by at least "
              f"{100 * th['min_gain']:.0f} %; explained when within {th['floor_ratio']} x the noise floor (structure "
              f"index (Q - lags) / n <= {th['floor_max_structure']}), or within "
              f"{th['explained_ratio']} x with a white error (Ljung-Box p >= {th['whiteness_alpha']}). Nominal "
              f"model: {rep['nominal']['combined_rmse_over_noise']:.3g}.", ""]
    lines += _candidate_table(rep["ranking"])
    if rep.get("pairs"):
        lines += ["", "Pairs (fitted together because the best single candidate leaves structure):", ""]
        lines += _candidate_table(rep["pairs"])
    if rep.get("skipped"):
        lines += ["", "Not tried: " + "; ".join(f"{k} ({v})" for k, v in rep["skipped"].items())]
    lines += ["", "![ranking](ranking.png)", ""]
    lines += ["## Extended model and gain", ""]
    if rep.get("extended_model"):
        chk = rep.get("extended_model_check", {})
        lines += [f"Written to `{rep['extended_model']}`; loaded back, it reproduces the scored predictions to "
                  f"{chk.get('max_relative_difference', 0):.1g} of each output's spread. Closed loop: "
                  f"{rep['extended_model_closed_loop']['message']}.", "",
                  "| output | held-out NRMSE nominal | held-out NRMSE extended | gain % |", "| --- | ---: | ---: | ---: |"]
        for o, v in rep["gain_by_output"].items():
            lines.append(f"| {o} | {fmt_num(v['nominal'], '.4f')} | {fmt_num(v['extended'], '.4f')} | "
                         f"{fmt_num(v['gain_percent'], '+.1f')} |")
    else:
        lines.append("No extended model: no candidate lowered the held-out error significantly.")
    lines.append("")
    if rep.get("structure_search"):
        lines += ["## Structure search", "", "```"] + structure_lines(rep) + ["```", ""]
    return "\n".join(lines) + "\n"


def terminal_summary(rep: dict) -> str:
    lines = [f"diagnose {rep['model']} on {', '.join(r['name'] for r in rep['data'])}"]
    for n in rep["notes"]:
        lines.append(f"  note: {n}")
    if rep["verdict"] != "not_identifiable":
        for m in rep["misfit"]:
            finds = "; ".join(f["text"] for f in m["shape"]["findings"][:2])
            lines.append(f"  nominal {m['record']}/{m['output']}: NRMSE {m['nrmse']:.4f} (fit {m['fit_percent']:.1f} %), "
                         f"{m['shape']['rmse_over_noise']:.2f} x noise; {finds}")
        for r in rep["ranking"][:5]:
            lines.append(f"  {r['cause']:25s} held-out {r['validation_rmse_over_noise']:8.3g} x noise  "
                         f"gain {r['gain_percent']:+6.1f} %  {fmt_params(r['parameters'])}")
    lines.append(f"  {verdict_line(rep)}")
    lines.append(f"  {rep['reason']}")
    if rep.get("extended_model"):
        lines.append(f"  extended model: {rep['extended_model']}")
    lines += structure_lines(rep)
    if rep.get("report_dir"):
        lines.append(f"  report: {Path(rep['report_dir']) / 'REPORT.md'}")
    return "\n".join(lines)



def structure_lines(rep: dict) -> list[str]:
    """The structure search's path: each step's held-out error and parameters with their 95 % intervals."""
    search = rep.get("structure_search")
    if not search:
        return []
    lines = ["  structure search (forward: add the largest held-out gain, refit jointly, stop when not significant):"]
    for s in search["path"]:
        mark = "" if s["accepted"] else "  [rejected]"
        gain = "" if s["gain_percent_vs_previous"] is None else \
            f", {s['gain_percent_vs_previous']:+.1f} % (p = {fmt_num(s['p_value_vs_previous'], '.2g')})"
        lines.append(f"    {s['model']:45s} held-out NRMSE {fmt_num(s['nrmse_validation'], '.4f')}, "
                     f"{s['validation_rmse_over_noise']:.3g} x noise{gain}{mark}")
        if s["parameters"] and s["accepted"]:
            lines.append(f"      {fmt_params(s['parameters'], s.get('confidence_intervals'))}")
        if s["nrmse_by_record"]:
            lines.append("      per record: " + ", ".join(f"{k} {v:.3f}" for k, v in s["nrmse_by_record"].items()))
        adapted = (s.get("fitted_where") or {}).get("adapted")
        if adapted:
            for name, info in adapted.items():
                lines.append(f"      adapted {name} on its first {info['samples']} samples: "
                             f"{fmt_params(info['parameters'])}")
    lines.append(f"    stopped: {search['stopped']}")
    if search.get("model_file"):
        lines.append(f"    model: {search['model_file']}")
    return lines
