"""Compare the four contact formulations, classical and DDCM, on the paper's bar.

Run it as ``python examples/compare_formulations.py [OUT_DIR]``; the tests import it and call
:func:`main`.
"""

from __future__ import annotations

import sys

from ddcm_casadi import MaterialDataset, bar_model, compare
from ddcm_casadi.outputs.save import save_figures


def main(out_dir: str | None = None, *, n_data: int = 500):
    # The model: what the problem is (paper, Section 4).
    data = MaterialDataset.hookean(200e9, -0.05, 0.01, n_data, c=300e9)
    model = bar_model(length=1.0, area=1.0, youngs_modulus=200e9, dataset=data,
                      positions=[1.01 - 0.001 * k for k in range(21)])

    # Every formulation (with its options) x {classical, DDCM} on the same load path.
    result = compare(model, {"penalty": {"gamma": 1e4 * 200e9}, "augmented_lagrangian": {},
                             "fischer_burmeister": {}, "mpcc": {}})
    print(result.table())

    # Arrays of one run, e.g. the DDCM Fischer-Burmeister tip displacement and pressure.
    fb = result.arrays("ddcm", "fischer_burmeister")
    print("h [m]:", fb["load_parameter"][[0, 10, 20]], " p [Pa]:", fb["p"][[0, 10, 20], 0])

    if out_dir is not None:
        # The figures that suit the model (for the bar, the paper's Fig. 2).
        save_figures(result, out_dir)
    return result


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
