"""The paper's published numbers (LEGO-H appendix), for tables that set ours beside them.

Values are ``(mean, std)`` per metric, copied from ``shared/paper/lego_h_appendix.txt``.
Table 4 lists the full LEGO-H (unified student) on H1 and G1 under the main protocol (all
five categories, 512 robots); Table 8 lists the EP-H and RMA-B baselines per trail category
under its own protocol (256 robots, 25 scenes). The paper publishes no oracle numbers.
Tables 1-3 are the appendix's ablations (overall rows); :data:`PAPER_TABLES` pairs each
with the study of ours that answers it (``experiments/paper_tables.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# appendix Table 4: metric order SR, TC, TR, MEV, TTF, T2R
_T4 = ("SR", "TC", "TR", "MEV", "TTF", "T2R")
TABLE4 = {
    "h1": dict(zip(_T4, [(68.40, 1.34), (52.78, 1.30), (71.96, 2.37), (7.84, 0.92),
                         (7.46, 0.17), (4.95, 0.12)], strict=True)),
    "g1": dict(zip(_T4, [(63.96, 1.03), (38.94, 0.63), (62.21, 0.97), (5.33, 0.68),
                         (7.24, 0.22), (8.10, 0.08)], strict=True)),
}

# appendix Table 8: {category: {method: {metric: (mean, std)}}}
TABLE8 = {
    "randommix": {
        "EP-H": [(16.98, 0.85), (2.67, 0.14), (70.88, 1.41), (11.32, 1.83), (3.33, 0.13),
                 (9.73, 0.19)],
        "RMA-B": [(30.99, 0.95), (3.60, 0.37), (76.74, 1.13), (10.95, 1.70), (4.14, 0.20),
                  (6.79, 0.09)]},
    "ditch": {
        "EP-H": [(16.12, 0.66), (17.90, 0.62), (55.75, 0.58), (22.75, 1.63), (3.50, 0.08),
                 (11.88, 0.33)],
        "RMA-B": [(32.80, 1.56), (30.77, 0.59), (63.49, 1.42), (23.66, 1.63), (4.56, 0.18),
                  (6.37, 0.37)]},
    "hurdle": {
        "EP-H": [(46.54, 2.64), (57.04, 1.25), (68.95, 1.79), (8.77, 0.46), (6.44, 0.21),
                 (5.94, 0.14)],
        "RMA-B": [(83.04, 0.27), (76.72, 0.47), (83.04, 1.17), (12.90, 1.92), (9.24, 0.28),
                  (4.22, 0.04)]},
    "gap": {
        "EP-H": [(18.13, 1.19), (32.26, 0.48), (58.74, 1.21), (31.84, 2.00), (4.36, 0.20),
                 (12.15, 0.34)],
        "RMA-B": [(39.93, 1.55), (44.27, 1.06), (65.30, 1.32), (24.10, 2.09), (5.44, 0.24),
                  (7.99, 0.17)]},
    "forest": {
        "EP-H": [(63.29, 1.50), (1.04, 0.16), (82.61, 1.18), (6.18, 1.57), (8.96, 0.49),
                 (13.65, 0.08)],
        "RMA-B": [(64.81, 2.43), (1.86, 0.38), (81.59, 3.20), (5.69, 1.04), (10.18, 0.89),
                  (13.20, 0.24)]},
}
TABLE8 = {cat: {method: dict(zip(_T4, row, strict=True)) for method, row in methods.items()}
          for cat, methods in TABLE8.items()}

# appendix Table 1 (GRU vs causal transformers at the end of TC-ViTs): SR and TTF only
TABLE1 = {"w GRU": {"SR": (68.40, 1.34), "TTF": (7.46, 0.17)},
          "w CTs": {"SR": (27.85, 1.02), "TTF": (5.44, 0.34)}}
# appendix Table 2 (the action prior): full HLM vs a vanilla VAE
TABLE2 = {
    "full HLM": dict(zip(_T4, [(68.40, 1.34), (52.78, 1.30), (71.96, 2.37), (7.84, 0.92),
                               (7.46, 0.17), (4.95, 0.12)], strict=True)),
    "Vanilla VAE": dict(zip(_T4, [(53.49, 1.61), (43.00, 0.96), (64.52, 1.02), (9.26, 1.08),
                                  (6.30, 0.15), (6.02, 0.05)], strict=True)),
}
# appendix Table 3 (HLM as a plug-in supervision of EP-H)
TABLE3 = {
    "EP-H": dict(zip(_T4, [(28.80, 0.88), (25.98, 0.22), (64.16, 0.48), (12.44, 1.32),
                           (4.64, 0.13), (9.79, 0.16)], strict=True)),
    "EP-H + HLM": dict(zip(_T4, [(35.53, 1.30), (30.36, 0.89), (58.23, 0.76), (10.98, 1.40),
                                 (5.04, 0.16), (7.80, 0.37)], strict=True)),
}


@dataclass(frozen=True)
class PaperTable:
    """One of the paper's comparisons and the study of ours that answers it.

    ``columns`` maps the paper's column name to our row label in the study's table (the
    ``algo.name`` or ``robot.name`` of its jobs); ``numbers`` are the paper's, per
    category for Table 8 (``{category: {column: {metric: (mean, std)}}}``), else one
    ``{column: {metric: (mean, std)}}`` compared with our ``overall`` row.
    """

    name: str
    title: str
    study: str
    columns: dict[str, str]
    numbers: dict
    per_category: bool = False


PAPER_TABLES = (
    PaperTable("table1", "Appendix Table 1: GRU vs causal transformers (CTs) at the end of "
               "TC-ViTs", "ablation_temporal", {"w GRU": "unified", "w CTs": "unified_ct"},
               TABLE1),
    PaperTable("table2", "Appendix Table 2: the action prior, full HLM vs a vanilla VAE",
               "ablation_prior", {"full HLM": "unified", "Vanilla VAE": "unified_vae"}, TABLE2),
    PaperTable("table3", "Appendix Table 3: HLM as a plug-in supervision of EP-H",
               "plugin_hlm", {"EP-H": "ep_h", "EP-H + HLM": "ep_h_hlm"}, TABLE3),
    PaperTable("table4", "Appendix Table 4: LEGO-H on H1 and on G1", "robots",
               {"H1": "h1", "G1": "g1"}, {"H1": TABLE4["h1"], "G1": TABLE4["g1"]}),
    PaperTable("table8", "Appendix Table 8: EP-H vs RMA-B per trail category", "table8",
               {"EP-H": "ep_h", "RMA-B": "rma_b"}, TABLE8, per_category=True),
)


@dataclass(frozen=True)
class MainComparison:
    """The main paper's comparison: LEGO-H beside the baselines per trail category.

    ``methods`` maps the paper's name to our ``algo.name``; ``numbers`` holds the published
    values we have (``{category | "overall": {method: {metric: (mean, std)}}}``): Table 8's
    EP-H and RMA-B per category (its own protocol) and Table 4's LEGO-H overall (the main
    protocol); the main paper's own table is not in our notes, so the rest are ours alone.
    """

    title: str
    study: str
    methods: dict[str, str]
    numbers: dict


MAIN = MainComparison(
    "The main paper's comparison: LEGO-H beside RMA-H, RMA-B and EP-H per trail category",
    "benchmark", {"LEGO-H": "unified", "RMA-H": "rma_h", "RMA-B": "rma_b", "EP-H": "ep_h"},
    {"overall": {"LEGO-H": TABLE4["h1"]}, **{c: dict(m) for c, m in TABLE8.items()}})


def ordering(a: tuple[float, float], b: tuple[float, float], higher_is_better: bool) -> str:
    """Which of two (mean, std) cells is better: ``">"`` (a), ``"<"`` (b), or ``"="`` when
    the means lie within the larger std of each other (no ordering to compare); ``"?"``
    when either mean is NaN."""
    (ma, sa), (mb, sb) = a, b
    if math.isnan(ma) or math.isnan(mb):
        return "?"
    if abs(ma - mb) <= max(0.0 if math.isnan(sa) else sa, 0.0 if math.isnan(sb) else sb):
        return "="
    return ">" if (ma > mb) == higher_is_better else "<"
