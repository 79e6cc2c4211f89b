"""ANOVA of full factorial results with Fisher's F test and the paper's reduced effect models.

The paper (sec. 3.1, eqs 20-28) writes each response as the grand mean plus, for every significant
term, a vector (main effect) or a matrix (two-factor interaction) of effects over the levels::

    y = mean + E_A . A_A + E_C . A_C + A_C^t . E_CD . A_D

``A_X`` is the level-indicator vector of factor X ([1, 0]^t at level 1, [0, 1]^t at level 2) and
``E_X[i] = mean(y | X at level i) - mean``; interactions are the cell means with every lower-order
effect removed, so each vector/matrix sums to zero along every axis. For two levels this is the
+-1 coding with **level 1 -> +1**: the "coefficient at level 1" (the first entry, which the paper
prints) equals the OLS coefficient of that coding.

Significance: Fisher's F = MS_term / MS_error, p = P(F(df_term, df_error) > F), significant when
p < alpha. Error: pure error when the runs are replicated; without replicates the interactions of
order above ``max_order`` are pooled as error (default: 3- and higher-order interactions when there
are three or more factors, the two-factor interaction for two factors). With the paper's 2^4 tables
and alpha = 0.05 this reproduces the printed term sets of eqs (20)-(24), (26), (27); see docs/doe.md
for eqs (25) and (28).

The effects are computed from the balanced cell means (inclusion-exclusion over the term's
factors); the sums of squares, F and p come from statsmodels (``ols`` + ``anova_lm``), and the
reduced model is refitted with statsmodels to report its R^2.
"""
from __future__ import annotations

import dataclasses
import itertools
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from labtool.common.errors import FileFormatError, InputError

# response columns labtool knows (docs/architecture.md --json indicator keys; Tables 2 and 3) with units
RESPONSE_UNITS = {
    "MR13D_max_Nm": "N m", "MR13D_min_Nm": "N m", "dphi2_max_deg": "deg",
    "domega2_max_rad_s": "rad/s", "domega1_max_rad_s": "rad/s", "percussion_max_Ns": "N s",
    "jumps": "1", "impacts": "1", "xel_max_mm": "mm", "xel_min_mm": "mm",
}

_LEVEL_COL_RE = re.compile(r"^([A-Z])_([A-Za-z][A-Za-z0-9]*)_level$")
_REL_ZERO = 1e-12  # sums of squares below this fraction of the total are round-off


@dataclasses.dataclass(frozen=True)
class DesignFactor:
    """A factor as seen in a results table: letter, symbol, sorted level labels."""

    name: str
    symbol: str
    levels: tuple

    @property
    def column(self) -> str:
        return f"{self.name}_{self.symbol}_level"


@dataclasses.dataclass
class FactorialData:
    """A validated balanced full factorial: factors, responses, rows and replicates per cell."""

    factors: list[DesignFactor]
    responses: list[str]
    frame: pd.DataFrame
    replicates: int
    source: str = "<table>"


@dataclasses.dataclass
class Term:
    """One ANOVA term. ``effects`` has one axis per factor of the term, one entry per level."""

    name: str
    effects: np.ndarray
    df: int
    ss: float
    F: float | None = None
    p: float | None = None
    significant: bool = False
    pooled: bool = False

    @property
    def coefficient(self) -> float:
        """The effect with every factor of the term at level 1 (what the paper prints)."""
        return float(self.effects.flat[0])


@dataclasses.dataclass
class ResponseAnova:
    """ANOVA of one response: terms in order (main effects, then 2-factor, ...), error and model."""

    response: str
    mean: float
    terms: dict[str, Term]
    error_df: int
    error_ss: float
    error_source: str          # sentence saying what the error is
    pooled_terms: list[str]
    alpha: float
    r2_reduced: float | None = None
    note: str = ""


    @property
    def significant(self) -> list[str]:
        return [t.name for t in self.terms.values() if t.significant]

    def predict(self, levels: dict[str, int]) -> float:
        """The reduced model at one level combination (1-based level indices by factor letter)."""
        y = self.mean
        for t in self.terms.values():
            if t.significant:
                y += float(t.effects[tuple(levels[c] - 1 for c in t.name)])
        return y


# --------------------------------------------------------------------------------------------
# reading and validating a results table

def read_results(path: str | Path) -> FactorialData:
    """Read a CSV shaped like Tables 2/3 (``run``, ``<X>_<symbol>_level`` columns, responses)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"results file {path} does not exist")
    try:
        frame = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{path}: not a readable CSV file ({str(exc).strip()})") from None
    return validate_results(frame, source=str(path))


def validate_results(frame: pd.DataFrame, source: str = "<table>") -> FactorialData:
    """Check a results table is a balanced full factorial with complete numeric responses."""
    frame = frame.copy()
    frame.columns = [str(c).strip() for c in frame.columns]
    twice = sorted(set(frame.columns[frame.columns.duplicated()]))
    if twice:   # "jumps" and " jumps": one name once stripped (pandas renames only exact copies)
        raise InputError(f"{source}: column(s) {', '.join(twice)} given more than once; keep one of each")
    factors_cols, responses, unknown = [], [], []
    for c in frame.columns:
        if c == "run":
            continue
        if _LEVEL_COL_RE.match(c):
            factors_cols.append(c)
        elif c in RESPONSE_UNITS:
            responses.append(c)
        else:
            unknown.append(c)
    if unknown:
        raise InputError(f"{source}: unknown column(s) {', '.join(unknown)}; expected run, factor level "
                         f"columns like A_Fu_level and responses among {', '.join(RESPONSE_UNITS)}")
    if not factors_cols:
        raise InputError(f"{source}: no factor level columns (named like A_Fu_level)")
    if not responses:
        raise InputError(f"{source}: no response column (one of {', '.join(RESPONSE_UNITS)})")
    if len(frame) == 0:
        raise InputError(f"{source}: no rows")
    letters = [_LEVEL_COL_RE.match(c).group(1) for c in factors_cols]
    dup = sorted({x for x in letters if letters.count(x) > 1})
    if dup:
        raise InputError(f"{source}: factor letter(s) {', '.join(dup)} used by more than one column")
    factors = []
    for c in factors_cols:
        col = pd.to_numeric(frame[c], errors="coerce")
        bad = frame.index[col.isna()]
        if len(bad):
            raise InputError(f"{source}: factor column {c} has a missing or non-numeric level in row {bad[0] + 1}")
        frame[c] = col
        levels = tuple(sorted(col.unique()))
        name, symbol = _LEVEL_COL_RE.match(c).groups()
        if len(levels) < 2:
            raise InputError(f"{source}: factor {name} ({symbol}) has a single level ({levels[0]:g}); "
                             "a factor needs at least two levels: drop the column or vary it")
        factors.append(DesignFactor(name, symbol, levels))
    for r in responses:
        col = pd.to_numeric(frame[r], errors="coerce")
        bad = [i + 1 for i in np.flatnonzero(col.isna() | ~np.isfinite(col.to_numpy(dtype=float, na_value=np.nan)))]
        if bad:
            runs = frame["run"].iloc[[b - 1 for b in bad]].tolist() if "run" in frame else bad
            raise InputError(f"{source}: response {r} is missing or not a number in run(s) "
                             f"{', '.join(map(str, runs[:5]))}{' ...' if len(runs) > 5 else ''}")
        frame[r] = col.astype(float)
    counts = frame.groupby([f.column for f in factors]).size()
    n_cells = math.prod(len(f.levels) for f in factors)
    if len(counts) < n_cells:
        full = pd.MultiIndex.from_product([list(f.levels) for f in factors])
        missing = full.difference(counts.index if isinstance(counts.index, pd.MultiIndex)
                                  else pd.MultiIndex.from_arrays([counts.index]))
        example = ", ".join(f"{f.name}={v:g}" for f, v in zip(factors, missing[0] if len(factors) > 1 else [missing[0][0]]))
        raise InputError(f"{source}: not a full factorial: {n_cells - len(counts)} of {n_cells} level "
                         f"combinations have no run (e.g. {example})")
    if counts.nunique() != 1:
        raise InputError(f"{source}: unbalanced design: level combinations have between {counts.min()} and "
                         f"{counts.max()} runs; every combination needs the same number")
    return FactorialData(factors, responses, frame, int(counts.iloc[0]), source)


# --------------------------------------------------------------------------------------------
# effects and ANOVA

def all_terms(factors: list[DesignFactor], max_order: int | None = None) -> list[str]:
    """Term names in the usual order: A, B, ..., AB, AC, ..., ABC, ..."""
    letters = [f.name for f in factors]
    top = len(letters) if max_order is None else max_order
    return ["".join(s) for r in range(1, top + 1) for s in itertools.combinations(letters, r)]


def cell_means(data: FactorialData, response: str) -> np.ndarray:
    """Array of cell means, one axis per factor (level order = sorted labels)."""
    cols = [f.column for f in data.factors]
    m = data.frame.groupby(cols)[response].mean()
    shape = tuple(len(f.levels) for f in data.factors)
    full = pd.MultiIndex.from_product([list(f.levels) for f in data.factors]) if len(cols) > 1 else None
    values = m.reindex(full).to_numpy() if full is not None else m.reindex(list(data.factors[0].levels)).to_numpy()
    return values.reshape(shape)


def effects(means: np.ndarray, axes: tuple[int, ...]) -> np.ndarray:
    """Effect array of the term on ``axes`` of a balanced cell-mean array (sums to zero on each axis).

    Inclusion-exclusion: E_S = sum over subsets U of S of (-1)^(|S|-|U|) * mean over the axes not in U.
    """
    k = means.ndim
    out = np.zeros(tuple(means.shape[a] for a in axes))
    for r in range(len(axes) + 1):
        for sub in itertools.combinations(axes, r):
            other = tuple(a for a in range(k) if a not in sub)
            marg = means.mean(axis=other) if other else means
            # broadcast the marginal (axes = sub) into the term's axes
            shape = [means.shape[a] if a in sub else 1 for a in axes]
            out += (-1) ** (len(axes) - r) * np.asarray(marg).reshape(shape)
    return out


def default_max_order(n_factors: int, replicates: int) -> int:
    """Highest interaction order kept as a model term (the rest is pooled as error)."""
    if replicates > 1:
        return n_factors
    return 2 if n_factors >= 3 else 1


def analyze_response(data: FactorialData, response: str, alpha: float = 0.05,
                     max_order: int | None = None) -> ResponseAnova:
    """Effects, ANOVA with Fisher's F, and the reduced model of one response."""
    import statsmodels.formula.api as smf
    from statsmodels.stats.anova import anova_lm

    check_alpha(alpha)
    k = len(data.factors)
    order = default_max_order(k, data.replicates) if max_order is None else max_order
    if not 1 <= order <= k:
        raise InputError(f"interaction order must lie in 1..{k} for {k} factor(s), got {order}")
    letters = [f.name for f in data.factors]
    tested = all_terms(data.factors, order)
    pooled = [t for t in all_terms(data.factors) if t not in tested]
    n = len(data.frame)
    error_df = n - 1 - sum(_term_df(data, t) for t in tested)
    if error_df <= 0:
        raise InputError(f"{data.source}: no degrees of freedom left for the error with terms up to order "
                         f"{order} and {data.replicates} run(s) per cell; lower the interaction order "
                         "or replicate the runs")

    means = cell_means(data, response)
    y = data.frame[response].to_numpy(dtype=float)
    grand = float(y.mean())
    with np.errstate(over="ignore", invalid="ignore"):
        ss_total = float(((y - grand) ** 2).sum())
    if not math.isfinite(ss_total):
        raise InputError(f"{data.source}: response {response} has values too large to square "
                         f"(max |value| {np.abs(y).max():.3g}); rescale the column")
    spread = float(np.abs(y - grand).max())
    if spread > 0 and spread * spread * _REL_ZERO < np.finfo(float).tiny:
        # its squares underflow: a varying response was "constant", its effects all zero
        raise InputError(f"{data.source}: response {response} varies too little to square (largest deviation "
                         f"from its mean {spread:.3g}); rescale the column")

    frame = _model_frame(data, response)
    fit = smf.ols(_formula(tested), data=frame).fit()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # F = 0/0 when the response is constant
        table = anova_lm(fit, typ=1)
    ss_error = float(table.loc["Residual", "sum_sq"])
    if int(round(table.loc["Residual", "df"])) != error_df:  # pragma: no cover - guards the df algebra
        raise AssertionError("error degrees of freedom disagree with statsmodels")
    tiny = _REL_ZERO * max(ss_total, np.finfo(float).tiny)
    error_zero = ss_error <= tiny
    terms: dict[str, Term] = {}
    for t in all_terms(data.factors):
        axes = tuple(letters.index(c) for c in t)
        eff = effects(means, axes)
        if t in tested:
            row = table.loc[_patsy_name(t)]
            ss, df = float(row["sum_sq"]), int(round(row["df"]))
            if ss <= tiny:
                F, p = 0.0, 1.0
            elif error_zero:
                F, p = math.inf, 0.0   # exact fit: any real effect is infinitely significant
            else:
                F, p = float(row["F"]), float(row["PR(>F)"])
            terms[t] = Term(t, eff, df, ss, F, p, bool(p < alpha))
        else:
            terms[t] = Term(t, eff, _term_df(data, t), _ss_of(eff, n), pooled=True)

    if data.replicates > 1 and not pooled:
        error_source = f"pure error from {data.replicates} replicates per level combination ({error_df} df)"
    elif data.replicates > 1:
        error_source = (f"pure error from {data.replicates} replicates plus the pooled interactions "
                        f"{', '.join(pooled)} ({error_df} df)")
    else:
        error_source = (f"no replicates: the interactions {', '.join(pooled)} are pooled as error "
                        f"({error_df} df)")
    note = ""
    if ss_total <= np.finfo(float).tiny:
        note = "the response is constant: no effect can be tested"
    elif error_zero:
        note = "the pooled error is zero (the tested terms fit exactly): every non-zero term is significant"

    result = ResponseAnova(response, grand, terms, error_df, ss_error, error_source, pooled, alpha, note=note)
    sig = result.significant
    if sig and ss_total > 0:
        result.r2_reduced = float(smf.ols(_formula(sig), data=frame).fit().rsquared)
    elif ss_total > 0:
        result.r2_reduced = 0.0
    return result


def analyze(data: FactorialData, alpha: float = 0.05, max_order: int | None = None,
            responses: list[str] | None = None) -> dict[str, ResponseAnova]:
    """ANOVA of every (or the chosen) response of a validated results table."""
    chosen = data.responses if not responses else responses
    unknown = [r for r in chosen if r not in data.responses]
    if unknown:
        raise InputError(f"{data.source}: no response column {', '.join(unknown)}; "
                         f"the file has {', '.join(data.responses)}")
    return {r: analyze_response(data, r, alpha, max_order) for r in chosen}


def check_alpha(alpha: float) -> None:
    if not (isinstance(alpha, (int, float)) and math.isfinite(alpha) and 0.0 < alpha < 1.0):
        raise InputError(f"significance level alpha must lie strictly between 0 and 1, got {alpha}")


def _term_df(data: FactorialData, term: str) -> int:
    by = {f.name: len(f.levels) for f in data.factors}
    return math.prod(by[c] - 1 for c in term)


def _ss_of(eff: np.ndarray, n: int) -> float:
    # balanced design: every cell of the term's table holds n / size observations
    return float((eff ** 2).sum() * n / eff.size)


def _model_frame(data: FactorialData, response: str) -> pd.DataFrame:
    out = pd.DataFrame({"y": data.frame[response].to_numpy(dtype=float)})
    for f in data.factors:
        # level index 1..L (sorted labels), so that Sum coding drops the *last* level
        out[f"f{f.name}"] = data.frame[f.column].map({v: i + 1 for i, v in enumerate(f.levels)}).astype(int)
    return out


def _patsy_name(term: str) -> str:
    # columns are prefixed: a factor named C would shadow patsy's C()
    return ":".join(f"C(f{c}, Sum)" for c in term)


def _formula(terms: list[str]) -> str:
    return "y ~ " + " + ".join(_patsy_name(t) for t in terms)


# --------------------------------------------------------------------------------------------
# output: the paper's matrix form and the --json mapping

def _fmt(v: float, digits: int = 7) -> str:
    s = f"{v:.{digits}g}"
    return "0" if s in ("0", "-0") else s


def _vector(a: np.ndarray, digits: int) -> str:
    return "[" + "  ".join(_fmt(v, digits) for v in a) + "]"


def matrix_form(result: ResponseAnova, digits: int = 7) -> str:
    """The reduced model in the paper's matrix notation (eqs 20-28), one term per line."""
    lines = [f"{result.response} = {_fmt(result.mean, digits)}"]
    for t in result.terms.values():
        if not t.significant:
            continue
        if len(t.name) == 1:
            lines.append(f"    + {_vector(t.effects, digits)} x A_{t.name}")
        elif len(t.name) == 2:
            rows = "; ".join("  ".join(_fmt(v, digits) for v in row) for row in t.effects)
            lines.append(f"    + A_{t.name[0]}^t x [{rows}] x A_{t.name[1]}")
        else:
            flat = "  ".join(_fmt(v, digits) for v in t.effects.ravel())
            lines.append(f"    + E_{t.name}[{'x'.join(map(str, t.effects.shape))}, C order: {flat}]"
                         f" over {', '.join('A_' + c for c in t.name)}")
    if len(lines) == 1:
        lines.append("    (no significant term: the model is the mean)")
    return "\n".join(lines)


def to_json(results: dict[str, ResponseAnova]) -> dict:
    """response -> term -> {coefficient, F, p, significant, df, ...} (docs/architecture.md CLI contract).

    ``mean`` carries the grand mean; pooled terms carry ``pooled: true`` and null F/p; ``error``
    describes the error term. Terms with more than two levels also list every level's effect.
    """
    def num(v):
        if v is None:
            return None
        v = float(v)
        return v if math.isfinite(v) else None  # JSON has no inf: an exact fit's F is null, its p 0

    out = {}
    for r, res in results.items():
        d = {"mean": {"coefficient": res.mean, "F": None, "p": None, "significant": True, "df": 1}}
        for t in res.terms.values():
            entry = {"coefficient": num(t.coefficient), "F": num(t.F), "p": num(t.p),
                     "significant": bool(t.significant), "df": t.df, "sum_sq": num(t.ss)}
            if t.pooled:
                entry["pooled"] = True
            if t.effects.size > 2 ** len(t.name):
                entry["effects"] = t.effects.tolist()
            d[t.name] = entry
        d["error"] = {"df": res.error_df, "sum_sq": num(res.error_ss), "source": res.error_source,
                      "pooled": res.pooled_terms, "alpha": res.alpha, "r2_reduced": num(res.r2_reduced)}
        if res.note:
            d["error"]["note"] = res.note
        out[r] = d
    return out
