"""Draws docs/user-guide/figures/rattleback-spin-reversal.png and prints the measurements of the
rattleback section of the models guide: the spin ω₃ and the energy error of Kane and Levinson's
rattleback (gnipy.models.rattleback) started spinning at −5 rad/s with a rocking of 0.1 rad/s,
with gnipy's reference, sgni-trapezoid, dla and gni-trapezoid at h = 0.001 over 20 s.
Run: `python docs/_tools/rattleback_figure.py` (about two minutes)."""

import pathlib
import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import gnipy  # noqa: E402
from gnipy.models import rattleback as rb  # noqa: E402
from gnipy.plots.figure_parts import save_figure  # noqa: E402

if __name__ == "__main__":
    system = rb.build(omega=(0.1, 0.0, -5.0))
    runs = {"reference": gnipy.simulate(system, "reference", h=0.01, t_final=20.0)}
    for method in ("sgni-trapezoid", "dla", "gni-trapezoid"):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            runs[method] = gnipy.simulate(system, method, h=0.001, t_final=20.0, save_every=10, throw=False)
        flags = [str(w.message).splitlines()[0] for w in caught if issubclass(w.category, gnipy.QualitativeFailureWarning)]
        print(method, "healthy" if runs[method].healthy else "flagged:", *flags)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 6.0), sharex=True)
    for (name, run), style, color in zip(runs.items(), ("-", "--", ":", "-"), ("C0", "C1", "C2", "C3")):
        t = np.asarray(run.t)
        E = np.array([float(rb.energy(rb.PARAMS, q, v, R)) for q, v, R in zip(np.asarray(run.q), np.asarray(run.v),
                                                                              np.asarray(run.R))])
        lw = 2.0 if name == "reference" else 1.0
        top.plot(t, np.asarray(run.v)[:, 5], style, color=color, lw=lw,
                 label=name if name == "reference" else f"{name}, h = 0.001")
        if name != "reference":
            bottom.semilogy(t[1:], np.abs(E[1:] - E[0]) / abs(E[0]) + 1e-17, style, color=color, lw=lw, label=name)
        print(f"{name}: final spin {np.asarray(run.v)[-1, 5]:+.4f} rad/s, energy error {np.max(np.abs(E - E[0])) / abs(E[0]):.2e}")
    top.set_ylabel("spin ω₃ (rad/s)")
    top.set_title("Rattleback (Kane & Levinson 1982): spin reversal")
    top.legend(fontsize=8)
    bottom.set_ylabel("relative energy error")
    bottom.set_xlabel("t (s)")
    bottom.legend(fontsize=8)
    out = pathlib.Path(__file__).resolve().parents[1] / "user-guide" / "figures" / "rattleback-spin-reversal.png"
    fig.tight_layout()
    save_figure(fig, out, overwrite=True)
    print("written", out)
