"""REPORT.md and figures of the offline analysis: each claim of the paper's Sections 6 and 7 beside ours.

:func:`write_all` takes a multisignal and Section 7 pairs, runs
:mod:`phfdi.study.analysis`, draws the figures (:mod:`phfdi.study.figures`)
and writes ``REPORT.md`` and ``results.json``. Verdicts are computed from the
measured numbers; the reasons given for a difference are the mechanisms we
checked (see docs/analysis.md).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from phfdi_base.outputs import write_text

from . import figures
from .analysis import Options, PairResult, analyze_multisignal
from .multisignal import Multisignal

#: the paper's number for the compression claim (Section 6, Figure 34)
PAPER_NONZERO_PCT = 0.75
PAPER_GROUPS_TEXT = "{friction}, {healthy, backlash}, {dead-zone, saturation}"


@dataclass
class Claim:
    where: str
    paper: str
    ours: str
    verdict: str


def _fmt(x: float | None, digits: int = 3) -> str:
    return "-" if x is None or not np.isfinite(x) else f"{x:.{digits}g}"


def _range(a: np.ndarray, digits: int = 3) -> str:
    a = np.asarray(a)
    lo, hi = float(np.min(a)), float(np.max(a))
    return f"{lo:.{digits}g} %" if np.isclose(lo, hi) else f"{lo:.{digits}g} - {hi:.{digits}g} %"


def _cluster_run(s6: dict, features_prefix: str, method: str = "hierarchical", k_source: str = "given") -> dict | None:
    for r in s6["clustering"]["runs"]:
        if r["features"].startswith(features_prefix) and r["method"] == method and r["k_source"] == k_source:
            return r
    return None


def _groups_text(run: dict) -> str:
    classes, table = run["classes"], np.asarray(run["table"])
    parts = []
    for row in table:
        members = [f"{cls} {n}" if n != table[:, j].sum() else cls for j, (cls, n) in enumerate(zip(classes, row)) if n]
        parts.append("{" + ", ".join(members) + "}")
    return ", ".join(parts)


# ---- claims ----------------------------------------------------------------------------------------
def section6_claims(ms: Multisignal, s6: dict, opts: Options) -> list[Claim]:
    """The paper's Section 6 claims (decomposition, denoising, compression, clustering, severity) beside ours."""
    levels = sorted(s6["denoised"])
    claims = [_decomposition_claim(ms, s6["decomposition"])]
    claims += _edge_claims(ms, s6.get("edges"), opts, levels)
    claims.append(_denoise_residual_claim(ms, s6["denoise_residual"][levels[0]]))
    claims.append(_compression_claim(ms, s6["compression"], s6["decomposition"], opts.level))
    clusters = _cluster_claim(s6, opts.level)
    if clusters is not None:
        claims.append(clusters)
    severity = _severity_claim(s6.get("severity") or {})
    if severity is not None:
        claims.append(severity)
    return claims


def _decomposition_claim(ms: Multisignal, d: dict) -> Claim:
    """Figure 29: the shapes of the row decomposition."""
    n, m = ms.shape
    same_shape = (n, m) == (35, 1440)
    return Claim(
        "6, Fig. 29 (mdwtdec structure)",
        "Row decomposition of the 35 x 1440 multisignal with sym4 at level 7, 'sym' extension: "
        "ca 35x18, cd 7 sets",
        f"{n} x {m} rows, {d['wavelet']} level {d['level']} '{d['mode']}': ca {d['ca_shape'][0]}x{d['ca_shape'][1]}, "
        f"{len(d['cd_shapes'])} detail sets of lengths {', '.join(str(s[1]) for s in d['cd_shapes'])}; "
        f"perfect reconstruction to {_fmt(d['reconstruction_error'], 2)} {ms.unit}",
        "reproduced" if same_shape and d["ca_shape"][1] == 18 else
        "not comparable: this set is not 35 x 1440 (the shapes follow the same rule)")


def _edge_claims(ms: Multisignal, edges: dict | None, opts: Options, levels: list[int]) -> list[Claim]:
    """Figures 30 to 32: what the approximation and the denoising lose at the record's start and end."""
    lev = opts.level
    if not edges:
        return [Claim(
            "6, Fig. 30 to 32",
            f"Approximations at level {lev} lose the bumps at the start and end; denoising at a lower level keeps them",
            "not measured: the runs carry no noise-free signal (ph_true) to measure the loss against",
            "not checked")]
    a = edges[f"approximation level {lev}"]
    worst = max(ms.classes, key=lambda c: a[c]["rms_start"])
    worst_end = max(ms.classes, key=lambda c: a[c]["rms_end"])
    noise = edges["measured (no processing)"]["all"]["rms_all"]
    start_lost = a[worst]["rms_start"] > 5 * noise
    end_lost = a[worst_end]["rms_end"] > 5 * noise
    claims = [Claim(
        "6, Fig. 30, 31",
        f"Approximations at level {lev} capture the general shape but lose the bumps at the start and end",
        f"RMS error of A{lev} against the noise-free pH: {_fmt(a['all']['rms_all'])} {ms.unit} over the record "
        f"(mostly at the setpoint step); over the first {100 * opts.edge_fraction:g} %: "
        f"{_fmt(a[worst]['rms_start'])} {ms.unit} for the {worst} rows (their start transient); over the last "
        f"{100 * opts.edge_fraction:g} %: {_fmt(a[worst_end]['rms_end'])} {ms.unit} for the {worst_end} rows; "
        f"the bin-averaged measurement itself is off by {_fmt(noise)} {ms.unit}",
        f"{'reproduced' if start_lost and end_lost else 'partly' if start_lost or end_lost else 'differs'}: "
        f"the start transient is {'lost' if start_lost else 'kept'}; at the end "
        + (f"the {worst_end} rows' oscillation is averaged out (our runs end in steady states or limit "
           "cycles, not bumps)" if end_lost else "nothing is lost (our runs end in steady states)"))]
    if len(levels) >= 2:
        claims.append(_denoise_level_claim(ms, edges, opts, levels[0], levels[-1], worst))
    return claims


def _denoise_level_claim(ms: Multisignal, edges: dict, opts: Options, lo: int, hi: int, worst: str) -> Claim:
    """Figure 32: denoising at the lower level keeps more of the start and end."""
    d_lo, d_hi = edges[f"denoised level {lo}"], edges[f"denoised level {hi}"]
    ratio_start = d_hi[worst]["rms_start"] / max(d_lo[worst]["rms_start"], 1e-300)
    end_lo, end_hi = d_lo["all"]["rms_end"], d_hi["all"]["rms_end"]
    return Claim(
        "6, Fig. 32",
        f"Denoising at level {lo} instead of {hi} recovers the bumps at the start and end",
        f"{opts.denoise_rule}/{opts.shrink} thresholds, per-level noise: start error of the {worst} rows "
        f"{_fmt(d_lo[worst]['rms_start'])} {ms.unit} at level {lo} vs {_fmt(d_hi[worst]['rms_start'])} at level "
        f"{hi} ({ratio_start:.1f}x); end error {_fmt(end_lo)} vs {_fmt(end_hi)} {ms.unit} (all rows)",
        ("reproduced at the start" if ratio_start > 1.5 else "differs at the start") +
        ("; no difference at the end (nothing there to recover)" if abs(end_hi - end_lo) < 0.2 * end_hi
         else "; also at the end" if end_lo < end_hi else "; worse at the end"))


def _denoise_residual_claim(ms: Multisignal, res: dict) -> Claim:
    """Figure 32: the denoising residual of each class against white noise."""
    noisy = [c for c in ms.classes if res[c]["std_over_sigma"] < 1.5 and abs(res[c]["lag1_autocorrelation"]) < 0.4]
    not_noisy = [c for c in ms.classes if c not in noisy]
    return Claim(
        "6, Fig. 32",
        "The denoising residuals look like noise, except a few small remaining bumps",
        "residual std / noise sigma and lag-1 autocorrelation (white noise: 1 and 0): " + "; ".join(
            f"{c} {res[c]['std_over_sigma']:.1f} / {res[c]['lag1_autocorrelation']:.2f}" for c in ms.classes),
        ("reproduced" if not not_noisy else
         f"partly: noise-like for {', '.join(noisy) or 'no class'}; for {', '.join(not_noisy)} the residual holds "
         "the fault's own oscillation (limit cycle or start transient), which the threshold removes as if it were noise"))


def _compression_claim(ms: Multisignal, c: dict, d: dict, lev: int) -> Claim:
    """Figures 33, 34: how many coefficients keep the energy, and why the paper's figure is uniform."""
    raw, cen = c["raw_nonzero_pct"], c["centred_nonzero_pct"]
    n_a = d["ca_shape"][1]
    approx_pct = 100.0 * n_a / c["n_coefficients"]
    return Claim(
        "6, Fig. 33, 34",
        f"About {PAPER_NONZERO_PCT} % of the coefficients retain {100 * c['retain']:g} % of the energy, "
        "the same for every signal",
        f"as recorded: {_range(raw)} of {c['n_coefficients']} coefficients (energy kept {_range(c['raw_energy_pct'], 4)}); "
        f"each row about its mean: {_range(cen)}",
        ("reproduced" if abs(float(np.median(raw)) - PAPER_NONZERO_PCT) < 0.25 else
         f"differs in the number ({_fmt(float(np.median(raw)))} % vs {PAPER_NONZERO_PCT} %)") +
        ("; same for every row as recorded" if np.ptp(raw) < 0.1 else "; varies between rows") +
        (f". Why: the rows' mean (pH 8 to 12) carries almost all of their energy, and it sits in the {n_a} level-{lev} "
         f"approximation coefficients ({approx_pct:.2f} % of them) - the uniform figure says the rows are "
         f"offset, not how compressible the faults are; {PAPER_NONZERO_PCT} % of {c['n_coefficients']} would be "
         f"{PAPER_NONZERO_PCT / 100 * c['n_coefficients']:.0f} coefficients, fewer than the approximation itself"
         if np.ptp(raw) < 0.1 and abs(float(np.median(raw)) - approx_pct) < 0.2 else ""))


def _cluster_claim(s6: dict, lev: int) -> Claim | None:
    """Figures 35, 36: the paper's three clusters from the compressed approximation or the band energies."""
    primary = _cluster_run(s6, f"ca{lev}")
    if primary is None or primary["ari_paper"] is None:
        return None
    energy = _cluster_run(s6, "detail energies")
    energy_auto = _cluster_run(s6, "detail energies", k_source="silhouette")
    ours = (f"Ward on the compressed ca{lev} (like mdwtcluster), k = {primary['k']}: {_groups_text(primary)}, "
            f"ARI {primary['ari_paper']:.2f} against the paper's grouping")
    if energy is not None:
        ours += (f"; Ward on the log energies of ca{lev}, D{lev}..D1, k = {energy['k']}: {_groups_text(energy)}, "
                 f"ARI {energy['ari_paper']:.2f}")
        if energy_auto is not None:
            ours += f" (silhouette picks k = {energy_auto['k']})"
    if primary["ari_paper"] > 0.99:
        verdict = "reproduced"
    elif energy is not None and energy["ari_paper"] > 0.99:
        verdict = (f"reproduced from the band energies, not from the time-domain shape: the friction limit cycle "
                   f"averages out at level {lev}, so friction joins the healthy and backlash rows, while "
                   "dead-zone and saturation (same pH, the valve held below 50 %) split by severity")
    else:
        verdict = "differs"
    return Claim("6, Fig. 35, 36", f"Three clusters: {PAPER_GROUPS_TEXT}", ours, verdict)


def _severity_claim(sev: dict) -> Claim | None:
    """Section 7's severity claim, measured on the Section 6 set's severity variants."""
    if not sev:
        return None
    return Claim(
        "7, Fig. 55 (applied to the Section 6 set)",
        "The residuals give information about the fault severity",
        "Spearman rank correlation of the RMS of Res3A (fault row - healthy row with the same noise) with the "
        "severity factor: " + ", ".join(f"{k} {v['spearman']:.2f}" for k, v in sev.items()),
        "reproduced" if all(v["spearman"] > 0.7 for v in sev.values()) else
        "partly: " + ", ".join(f"{k}" for k, v in sev.items() if v["spearman"] <= 0.7) + " not monotone")


def section7_claims(pairs: Sequence[PairResult], opts: Options) -> list[Claim]:
    if not pairs:
        return []
    claims = []
    p0 = pairs[0]
    w = opts.residual_wavelets[0]
    rs = p0.twin[w]
    n = rs.lengths[-1]
    import pywt

    per_len = len(pywt.wavedec(np.zeros(n), w, mode="periodization", level=rs.level)[0])
    claims.append(Claim(
        "7, text after Fig. 48",
        "[C,L] = wavedec(x, 3, 'sym4'): the first element of L (scaling coefficients at level 3) is 256",
        f"L = [{', '.join(map(str, rs.lengths))}] for our {n}-sample run ({per_len} with periodization)",
        "differs, as it must: 256 = 2048 / 2^3 is a 2048-sample signal under periodization; the paper's code "
        "line decomposes `wecg`, MATLAB's example ECG, not a pH run"))
    claims.append(Claim(
        "7, Fig. 49, 56",
        "The faulty pH is perfectly reconstructed from its level-3 coefficients",
        "; ".join(f"{p.fault}: largest error {max(r.reconstruction_error for r in p.twin.values()):.1e} pH "
                  f"({', '.join(p.twin)})" for p in pairs),
        "reproduced"))
    twin_txt, real_txt = [], []
    for p in pairs:
        for wv in p.twin:
            det = p.twin_detection[wv]
            twin_txt.append(f"{p.fault}/{wv}: " + ", ".join(
                f"Res{b[1:]}{b[0]} {_fmt(det[b].first_alarm_s, 5)} s" for b in det))
            if wv in p.realistic_detection:
                rd = p.realistic_detection[wv]
                real_txt.append(f"{p.fault}/{wv}: " + ", ".join(
                    f"Res{b[1:]}{b[0]} {_fmt(rd[b].first_after_onset_s, 5) if rd[b].first_after_onset_s else 'none'}"
                    + (f" ({rd[b].false_alarms} false)" if rd[b].false_alarms else "") for b in rd))
    onset = p0.onset_s
    twin_ok = all(d.first_alarm_s is not None and (onset is None or d.first_alarm_s >= onset)
                  for p in pairs for det in p.twin_detection.values() for d in det.values())
    ours = ("first alarm, paper's residual (healthy twin with the same noise): " + "; ".join(twin_txt))
    if real_txt:
        ours += (f". Realistic residual (healthy reference with its own noise, thresholds from a second healthy "
                 f"run, trailing RMS of {opts.detect_window} coefficients): " + "; ".join(real_txt))
    a_band = f"A{opts.residual_level}"
    a_detects = real_txt and all(p.realistic_detection[wv][a_band].first_after_onset_s is not None
                                 for p in pairs for wv in p.realistic_detection)
    d_quiet = real_txt and all(_none_or_after(p.realistic_detection[wv][b].first_after_onset_s, (onset or 0) + 1000)
                               for p in pairs for wv in p.realistic_detection
                               for b in p.realistic_detection[wv] if b.startswith("D"))
    verdict = "reproduced with the paper's residual: every band is exactly 0 until the fault acts" if twin_ok \
        else "differs"
    if real_txt:
        verdict += ("; with a realistic reference only Res3A finds it (the faults act at 30 to 200-s scales, "
                    "the details D1-D3 hold the sensor noise)" if a_detects and d_quiet else
                    "; with a realistic reference see the detection table")
    claims.append(Claim(
        "7, Fig. 52-55, 58-61",
        f"The residuals Res1D, Res2D, Res3D, Res3A reveal the fault injection instant "
        f"(paper: 7000 s; here {_fmt(onset, 5)} s)",
        ours, verdict))
    cps = []
    found: dict[str, list[bool]] = {}
    for p in pairs:
        for cp in p.change_points:
            cps.append(f"{p.fault}, {cp.input}: " +
                       (f"{cp.nearest_s:.0f} s (error {round(cp.error_s):+d} s)"
                        if cp.nearest_s is not None and cp.error_s is not None
                        else f"none near the onset (found: {', '.join(f'{t:.0f}' for t in cp.faulty_s) or 'none'})") +
                       f"; healthy counterpart: {', '.join(f'{t:.0f}' for t in cp.healthy_s) or 'none'}")
            found.setdefault(cp.input, []).append(cp.nearest_s is not None)
    recipe = [k for k in found if "recipe" in k]
    others_ok = [k for k in found if k not in recipe and all(found[k])]
    verdict = ("reproduced with MATLAB's recipe" if recipe and all(found[recipe[0]]) else
               "not with MATLAB's recipe on the pH (its level-1 details hold only the sensor noise)")
    if others_ok:
        verdict += "; found in " + " and in ".join(k.split(":")[0] + " " + k.split(":")[1].strip() for k in others_ok)
    claims.append(Claim(
        "7, introduction (wvarchg)",
        "Changes in a signal's variance, found with 1-D wavelet analysis, locate the fault",
        " | ".join(cps), verdict))
    return claims


def _none_or_after(t_s: float | None, limit_s: float) -> bool:
    """No alarm, or one after ``limit_s``."""
    return t_s is None or t_s > limit_s


def beyond_the_paper(ms: Multisignal, s6: dict, pairs: Sequence[PairResult], opts: Options) -> list[str]:
    """Findings the paper does not state, each computed from this run's numbers."""
    out = []
    rules = s6.get("denoise_rules_rms")
    edges = s6.get("edges")
    if rules and edges:
        best = min(rules, key=rules.get)
        paper = f"{opts.denoise_rule}/{opts.shrink}/level {opts.denoise_levels[0]}"
        raw = edges["measured (no processing)"]["all"]["rms_all"]
        text = (f"Denoising rule: on these rows `{best}` comes closest to the noise-free pH "
                f"({_fmt(rules[best])} {ms.unit} RMS) against {_fmt(rules.get(paper))} {ms.unit} for the paper's "
                f"setting (`{paper}`)")
        if rules.get(paper, 0) > raw:
            text += (f"; the paper's setting is further from the truth than the unprocessed (bin-averaged) "
                     f"measurement ({_fmt(raw)} {ms.unit}): its threshold shaves real features (the setpoint "
                     "step, the limit cycles) along with the noise")
        out.append(text + ".")
    sev = s6.get("severity") or {}
    if "deadzone" in sev and "saturation" in sev:
        a, b = np.array(sev["deadzone"]["res_a_rms"]), np.array(sev["saturation"]["res_a_rms"])
        if len(a) == len(b):
            diff = float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))
            out.append(f"Dead-zone and saturation give the same pH: their Res3A RMS differ by at most "
                       f"{100 * diff:.2g} % row by row. At a given severity both cap the valve at the same opening "
                       "(the dead-zone by shifting the command by half its width, the saturation by clipping it), "
                       "so the pH cannot tell them apart; the valve position against the command can.")
    for p in pairs:
        rd = {w: d[f"A{opts.residual_level}"] for w, d in p.realistic_detection.items()}
        if rd and p.onset_s is not None:
            delays = ", ".join(f"{w} {d.first_after_onset_s - p.onset_s:.0f} s" if d.first_after_onset_s else f"{w} none"
                               for w, d in rd.items())
            falses = sum(d.false_alarms for d in rd.values())
            out.append(f"{p.fault}: without a noise-free twin, Res{opts.residual_level}A against a healthy "
                       f"reference raises its first alarm after {delays} ({falses} false alarms before the onset).")
    return out


# ---- markdown --------------------------------------------------------------------------------------
def _table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c).replace("|", "/") for c in row) + " |" for row in rows]
    return "\n".join(out)


def markdown(ms: Multisignal, s6: dict, pairs: Sequence[PairResult], opts: Options, context: dict,
             figure_files: Sequence[str]) -> str:
    """REPORT.md: the data, the claims table, Sections 6 and 7 in detail, findings beyond the paper, notes."""
    claims = section6_claims(ms, s6, opts) + section7_claims(pairs, opts)
    lines = [
        "# Offline wavelet analysis: the paper's Sections 6 and 7, claim by claim",
        "",
        f"Produced by `{context.get('command', 'phfdi analyze')}`.",
        "",
        "## Data",
        "",
        context.get("data", ""),
        "",
        f"Multisignal: {ms.shape[0]} rows x {ms.shape[1]} samples of `{ms.signal}` ({ms.unit}), classes "
        + ", ".join(f"{c} ({len(ms.rows(c))})" for c in ms.classes) + ".",
        "",
        "## Claims",
        "",
        _table(["Paper (section, figure)", "Paper's claim", "Ours (measured)", "Verdict"],
               [(c.where, c.paper, c.ours, c.verdict) for c in claims]),
        "",
    ]
    lines += _section6_lines(ms, s6, opts)
    lines += _section7_lines(ms, pairs, opts)
    beyond = beyond_the_paper(ms, s6, pairs, opts)
    if beyond:
        lines += ["## Beyond the paper", ""] + [f"- {b}" for b in beyond] + [""]
    lines += _notes_lines(context)
    lines += [f"- [{f}]({f})" for f in figure_files]
    return "\n".join(lines) + "\n"


def _section6_lines(ms: Multisignal, s6: dict, opts: Options) -> list[str]:
    """Section 6 in detail: approximations and denoising, compression, clustering, severity."""
    lines = ["## Section 6 in detail", "", "### Approximations and denoising (Figures 30 to 32)", ""]
    lines += _edge_lines(ms, s6, opts)
    res = s6["denoise_residual"]
    lines += [
        "Denoising residual (measured - denoised) per class: std over the estimated noise sigma, lag-1 "
        "autocorrelation, largest |residual| over sigma (white noise: about 1, 0, 3 to 4).",
        "",
        _table(["level", "class", "std / sigma", "lag-1 autocorrelation", "max / sigma"],
               [(lev, c, f"{r[c]['std_over_sigma']:.2f}", f"{r[c]['lag1_autocorrelation']:.2f}",
                 f"{r[c]['max_abs_over_sigma']:.1f}") for lev, r in res.items() for c in ms.classes]),
        "",
        "### Compression (Figures 33, 34)",
        "",
    ]
    comp = s6["compression"]
    lines += [
        _table(["class", "non-zero as recorded", "energy kept", "non-zero, row about its mean", "energy kept"],
               [(c, _range(comp["raw_nonzero_pct"][ms.rows(c)]), _range(comp["raw_energy_pct"][ms.rows(c)], 4),
                 _range(comp["centred_nonzero_pct"][ms.rows(c)]), _range(comp["centred_energy_pct"][ms.rows(c)], 4))
                for c in ms.classes]),
        "",
        "### Clustering (Figures 35, 36)",
        "",
        "Adjusted Rand index (ARI) against the paper's grouping " + PAPER_GROUPS_TEXT +
        " and against our five classes; k given (the paper's 3) or chosen by the largest mean silhouette of the "
        "hierarchical clustering.",
        "",
        _table(["features", "method", "k", "clusters (class counts)", "ARI paper", "ARI classes"],
               [(r["features"], r["method"], f"{r['k']} ({r['k_source']})", _groups_text(r),
                 _fmt(r["ari_paper"]), _fmt(r["ari_classes"])) for r in s6["clustering"]["runs"]]),
        "",
    ]
    sev = s6.get("severity") or {}
    if sev:
        lines += [
            "### Severity",
            "",
            _table(["fault", "severity factors", "RMS of Res3A", "Spearman"],
                   [(k, ", ".join(f"{f:.2f}" for f in v["factors"]), ", ".join(f"{r:.3g}" for r in v["res_a_rms"]),
                     f"{v['spearman']:.2f}") for k, v in sev.items()]),
            "",
        ]
    return lines


def _edge_lines(ms: Multisignal, s6: dict, opts: Options) -> list[str]:
    """The reconstructions' errors against the noise-free pH (none without ``ph_true``)."""
    edges = s6.get("edges")
    if not edges:
        return []
    return [
        f"RMS error against the noise-free pH (`ph_true`, resampled the same way), {ms.unit}: over the record, "
        f"over its first and last {100 * opts.edge_fraction:g} %, all rows (and the class with the largest "
        "start error).",
        "",
        _table(["Reconstruction", "whole record", "start", "end", "start, worst class"],
               [(name, _fmt(e["all"]["rms_all"]), _fmt(e["all"]["rms_start"]), _fmt(e["all"]["rms_end"]),
                 max(((c, e[c]["rms_start"]) for c in ms.classes), key=lambda kv: kv[1])[0] + " " +
                 _fmt(max(e[c]["rms_start"] for c in ms.classes)))
                for name, e in edges.items()]),
        "",
        "Every threshold rule against the noise-free pH (mean RMS error over rows; per-level noise "
        "estimate; the paper's MATLAB example uses the universal rule):",
        "",
        _table(["rule / shrinkage / level", f"RMS error ({ms.unit})"],
               [(k, _fmt(v)) for k, v in sorted(s6["denoise_rules_rms"].items(), key=lambda kv: kv[1])]),
        "",
    ]


def _section7_lines(ms: Multisignal, pairs: Sequence[PairResult], opts: Options) -> list[str]:
    """Section 7 in detail: each residual's first alarm and the variance change points (or why not run)."""
    if not pairs:
        return ["## Section 7", "", "Not run: it needs a faulty run whose metadata states the fault onset and a "
                "healthy run of the same length (simulated runs and runs saved by `--save-runs` carry both).", ""]
    return [
        "## Section 7 in detail",
        "",
        f"Fault onset {_fmt(pairs[0].onset_s, 5)} s. An alarm is dated when its coefficient can first be "
        "computed. Paper's residual: first non-zero coefficient of faulty - healthy twin (same noise). "
        "Realistic residual: faulty - healthy reference with its own noise; alarm when the trailing RMS over "
        f"{opts.detect_window} coefficients exceeds {opts.detect_margin} x the largest seen between two other "
        "healthy runs.",
        "",
        _table(["fault", "wavelet", "residual", "paper's residual: first alarm (s)",
                "realistic: first alarm after onset (s)", "delay (s)", "false alarms before onset",
                f"threshold ({ms.unit})"], _detection_rows(pairs)),
        "",
        "Variance change points (wvarchg, K_max = "
        f"{opts.max_changes}, minimum distance {opts.min_distance} coefficients); a change within "
        f"+/-{opts.onset_tolerance_s:g} s of the onset counts as finding it:",
        "",
        _table(["fault", "input", "change points, faulty run (s)", "healthy counterpart (s)",
                "error at onset (s)"],
               [(p.fault, cp.input, ", ".join(f"{t:.0f}" for t in cp.faulty_s) or "none",
                 ", ".join(f"{t:.0f}" for t in cp.healthy_s) or "none",
                 "-" if cp.error_s is None else f"{round(cp.error_s):+d}") for p in pairs for cp in p.change_points]),
        "",
    ]


def _detection_rows(pairs: Sequence[PairResult]) -> list[tuple]:
    """One row per (fault, wavelet, band): the paper's residual's first alarm beside the realistic one's."""
    rows = []
    for p in pairs:
        for wv in p.twin:
            for b, dd in p.twin_detection[wv].items():
                rd = p.realistic_detection.get(wv, {}).get(b)
                rows.append((p.fault, wv, f"Res{b[1:]}{b[0]}", _fmt(dd.first_alarm_s, 5),
                             "-" if rd is None else _fmt(rd.first_after_onset_s, 5),
                             "-" if rd is None or rd.first_after_onset_s is None or p.onset_s is None
                             else f"{rd.first_after_onset_s - p.onset_s:.0f}",
                             "-" if rd is None else rd.false_alarms,
                             "-" if rd is None else f"{rd.threshold:.3g}"))
    return rows


def _notes_lines(context: dict) -> list[str]:
    """Notes on the paper's sources and our tools, the timings, and the figures heading."""
    return [
        "## Notes",
        "",
        "- The paper's Section 6 follows MATLAB's documentation example *Multisignal 1-D Wavelet Analysis* "
        "(35 days x 1440 minutes of electrical load, `elec35_nor`) closely, down to its sentences; its "
        "`dataSize: [35 1440]` is that example's. Our set is built to the same shape from simulated pH runs, so "
        "shapes compare exactly and the numbers compare as behaviours, not digits.",
        "- MATLAB's `mdwtcluster`, `mswcmp`, `wden` and `wvarchg` are rebuilt on PyWavelets and SciPy "
        "(`wavelet_fdi`); PyWavelets' `symmetric` mode is MATLAB's `'sym'` and gives the same coefficient counts.",
        f"- Timings: {context.get('timings', '')}",
        "",
        "## Figures",
        "",
    ]


# ---- everything --------------------------------------------------------------------------------------
def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist() if x.ndim <= 1 and x.size <= 64 else f"array{list(x.shape)}"
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return x


def _pair_summary(p: PairResult) -> dict:
    return {
        "fault": p.fault, "onset_s": p.onset_s, "signal": p.signal,
        "lengths": {w: r.lengths for w, r in p.twin.items()},
        "reconstruction_error": {w: r.reconstruction_error for w, r in p.twin.items()},
        "twin_detection": {w: {b: vars(d) for b, d in det.items()} for w, det in p.twin_detection.items()},
        "realistic_detection": {w: {b: vars(d) for b, d in det.items()} for w, det in p.realistic_detection.items()},
        "change_points": [vars(cp) for cp in p.change_points],
    }


def write_all(ms: Multisignal, pairs_fn: Callable[[], Sequence[PairResult]] | Sequence[PairResult], out_dir: Path,
              opts: Options | None = None, context: dict | None = None, paper_grouping: dict | None = None,
              figures_on: bool = True, say: Callable[[str], None] = lambda s: None) -> dict:
    """Analyse, draw, write REPORT.md and results.json into ``out_dir``; returns the results."""
    opts = opts or Options()
    context = dict(context or {})
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    say(f"Section 6: analysing the {ms.shape[0]} x {ms.shape[1]} multisignal")
    t0 = time.perf_counter()
    s6 = analyze_multisignal(ms, opts, paper_grouping)
    t_s6 = time.perf_counter() - t0
    say("Section 7: residuals and change points")
    t0 = time.perf_counter()
    pairs = list(pairs_fn() if callable(pairs_fn) else pairs_fn)
    t_s7 = time.perf_counter() - t0
    files: list[str] = []
    t0 = time.perf_counter()
    if figures_on:
        say("figures")
        files = [p.name for p in _figures(ms, s6, pairs, opts, out_dir)]
    t_fig = time.perf_counter() - t0
    timing = f"Section 6 analysis {t_s6:.2f} s, Section 7 {t_s7:.2f} s, figures {t_fig:.1f} s"
    context["timings"] = (context.get("timings", "") + "; " if context.get("timings") else "") + timing
    write_text(out_dir / "REPORT.md", markdown(ms, s6, pairs, opts, context, files), overwrite=True)
    summary = {k: v for k, v in s6.items() if k not in ("approximations", "denoised", "compressed",
                                                           "compressed_centred", "linkage")}
    write_text(out_dir / "results.json", json.dumps(_jsonable({
        "section6": summary, "section7": [_pair_summary(p) for p in pairs], "timings": context["timings"],
    }), indent=1), overwrite=True)
    return {"section6": s6, "section7": pairs, "files": files, "timings": context["timings"]}


def _figures(ms: Multisignal, s6: dict, pairs: Sequence[PairResult], opts: Options, out: Path) -> list[Path]:
    lev = opts.level
    files = [
        figures.multisignal_overview(ms, out / "fig27_multisignal.png"),
        figures.multisignal_surface(ms, out / "fig28_surface.png"),
        figures.wavelet_functions(opts.wavelet, out / f"fig29_{opts.wavelet}.png"),
        figures.approximations(ms, s6["approximations"][lev], lev, out / f"fig30_approximations_level{lev}.png"),
        figures.approximation_groups(ms, s6["approximations"][lev], lev,
                                     [("healthy", "backlash", "friction"), ("deadzone", "saturation")],
                                     out / "fig31_groups.png"),
        figures.denoising(ms, s6["denoised"], out / "fig32_denoising.png", opts.edge_fraction),
        figures.compression(ms, s6["compressed"], s6["compression"]["raw_nonzero_pct"], opts.retain,
                            out / "fig33_compression.png"),
        figures.nonzero_bars(ms, s6["compression"]["raw_nonzero_pct"], s6["compression"]["centred_nonzero_pct"],
                             opts.retain, PAPER_NONZERO_PCT, out / "fig34_nonzero.png"),
    ]
    for prefix, tag in ((f"ca{lev}", "ca"), ("detail energies", "energy")):
        run = _cluster_run(s6, prefix)
        if run is None:
            continue
        title = f"Ward clustering of {run['features']}, k = {run['k']}"
        files.append(figures.clusters(ms, run["labels"], title, out / f"fig35_clusters_{tag}.png"))
        files.append(figures.partition(run["classes"], run["table"], title, out / f"fig36_partition_{tag}.png"))
        z = s6["linkage"].get(run["features"])
        if z is not None:
            files.append(figures.dendrogram(z, ms.names, f"Dendrogram: {run['features']}",
                                            out / f"dendrogram_{tag}.png"))
    if s6.get("severity"):
        files.append(figures.severity(s6["severity"], opts.residual_level, ms.unit, out / "severity.png"))
    w = opts.residual_wavelets[0]
    # the paper's figure numbers for its two Section 7 faults; other faults get names only
    numbers = {"backlash": ("fig40_42", "fig49", "fig50", "fig52_55"),
               "friction": ("fig41_43", "fig56", "fig57", "fig58_61")}
    for p in pairs:
        n_runs, n_rec, n_cf, n_res = numbers.get(p.fault, ("fig", "fig", "fig", "fig"))
        tag = f"_{p.fault}"
        rs = p.twin[w]
        files += [
            figures.healthy_and_faulty(p, "pH", out / f"{n_runs}_runs{tag}.png"),
            figures.reconstruction(p, w, "pH", out / f"{n_rec}_reconstruction{tag}.png"),
            figures.band_panels(rs, "faulty", f"{w} coefficients of the faulty signal ({p.fault})", "pH",
                                out / f"{n_cf}_coefficients{tag}.png", p.onset_s),
            figures.band_panels(rs, "residual", f"Residuals of the {w} coefficients, faulty - healthy twin "
                                f"({p.fault})", "pH", out / f"{n_res}_residuals{tag}.png", p.onset_s),
            figures.change_points(p, "pH", out / f"changepoints{tag}.png"),
        ]
        if w in p.realistic:
            det = p.realistic_detection[w]
            files.append(figures.band_panels(p.realistic[w], "residual",
                                             f"Realistic residuals, faulty - healthy reference with its own noise "
                                             f"({p.fault}, {w})", "pH", out / f"realistic_residuals{tag}.png",
                                             p.onset_s, {b: d.threshold for b, d in det.items()},
                                             opts.detect_window, {b: d.first_alarm_s for b, d in det.items()}))
    if pairs:
        files.append(figures.band_panels(pairs[0].twin[w], "healthy", f"{w} coefficients of the healthy signal",
                                         "pH", out / "fig51_coefficients_healthy.png"))
    return files
