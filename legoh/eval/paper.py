"""The paper's published numbers (LEGO-H appendix), for tables that set ours beside them.

Values are ``(mean, std)`` per metric, copied from ``shared/paper/lego_h_appendix.txt``.
Table 4 lists the full LEGO-H (unified student) on H1 and G1 under the main protocol (all
five categories, 512 robots); Table 8 lists the EP-H and RMA-B baselines per trail category
under its own protocol (256 robots, 25 scenes). The paper publishes no oracle numbers.
"""

from __future__ import annotations

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
