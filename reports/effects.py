"""The DOE's effects figure: main effects and two-factor interactions of a factorial's results
(the ANOVA of labtool.models.study.anova), levels shown as values in their units."""
from __future__ import annotations

from labtool.common.names import shown


def heading(d, f) -> str:
    """How a factor is named in a table or figure: its heading with the unit, else its symbol."""
    return f.heading if f is not None else f"{d.symbol} [level]"


def level(d, f, k: int) -> str:
    """Level ``k`` (1-based) of a factor: its value with the unit, else its number."""
    return f.level_text(k) if f is not None else f"{d.symbol} level {k}"


def plot_effects(data, out, path, physical=None) -> None:
    """One row per response: main effects (mean at each level of each factor, Minitab style) and
    one interaction panel per pair of factors (cell means); significant terms are drawn solid.

    Parameters
    ----------
    data : labtool.models.study.anova.FactorialData
        The factorial's results table (``anova.read_results``).
    out : dict
        The ANOVA of each response (``anova.analyze``).
    path : path
        The PNG to write.
    physical : list, optional
        Each factor's values and unit (``labtool.models.study.doe.Factor``, None: level numbers
        only), as ``labtool doe analyze --factors`` finds them.
    """
    import itertools

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from labtool.models.study.anova import RESPONSE_UNITS, cell_means
    from labtool.reports.figures import OKABE_ITO as PALETTE

    OKABE_ITO = [PALETTE[k] for k in ("blue", "vermillion", "green", "purple", "orange", "sky")]

    factors = data.factors
    physical = physical or [None] * len(factors)
    pairs = list(itertools.combinations(range(len(factors)), 2))
    ncol = 1 + len(pairs)
    nrow = len(out)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.0 + 2.4 * ncol, 2.6 * nrow), squeeze=False)
    for row, (resp, res) in enumerate(out.items()):
        m = cell_means(data, resp)
        ax = axes[row][0]
        x0, ticks, labels = 0, [], []
        for i, f in enumerate(factors):
            other = tuple(a for a in range(m.ndim) if a != i)
            means = m.mean(axis=other) if other else m
            xs = np.arange(x0, x0 + len(f.levels))
            sig = res.terms[f.name].significant
            ax.plot(xs, means, "o-" if sig else "o--", color=OKABE_ITO[i % len(OKABE_ITO)], lw=1.0,
                    label=f"{f.name}: {heading(f, physical[i])}")
            ticks += list(xs)
            labels += [level(f, physical[i], k + 1).replace(" = ", " ") for k in range(len(f.levels))]
            x0 += len(f.levels) + 1
        ax.axhline(res.mean, color="0.5", lw=0.8)
        ax.set_xticks(ticks, labels, fontsize=6, rotation=90)
        ax.set_ylabel(f"{resp} [{RESPONSE_UNITS.get(resp, '')}]", fontsize=8)
        ax.set_title("main effects (solid: significant)", fontsize=8)
        ax.legend(fontsize=6, loc="best")
        for j, (a, b) in enumerate(pairs, 1):
            ax = axes[row][j]
            other = tuple(k for k in range(m.ndim) if k not in (a, b))
            cm = m.mean(axis=other) if other else m
            name = factors[a].name + factors[b].name
            term = res.terms.get(name)
            style = "-" if term is not None and term.significant else "--"
            for lb in range(cm.shape[1]):
                ax.plot(np.arange(1, cm.shape[0] + 1), cm[:, lb], "o" + style, color=OKABE_ITO[lb % len(OKABE_ITO)],
                        lw=1.0, label=level(factors[b], physical[b], lb + 1))
            pa = physical[a]
            ax.set_xticks(np.arange(1, cm.shape[0] + 1),
                          [f"{v:g}" for v in pa.levels] if pa is not None else [str(k) for k in range(1, cm.shape[0] + 1)])
            ax.set_xlabel(f"{factors[a].name}: {heading(factors[a], pa)}", fontsize=7)
            ax.set_title(f"{name}" + (" (pooled)" if term is not None and term.pooled else
                                      " *" if term is not None and term.significant else ""), fontsize=8)
            ax.tick_params(labelsize=6)
            ax.legend(fontsize=6)
    # the file name is text, not mathtext ('$x^$' in a name raised a ParseException) nor markup
    fig.suptitle(f"{shown(data.source)}: main effects and two-factor interactions (cell means)", fontsize=9,
                 parse_math=False)
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=90)
    plt.close(fig)
