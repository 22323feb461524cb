"""Rates with exact (Clopper–Pearson) confidence bounds, and the summary of a sweep.

Per event (an encounter with at least one collision, one protected-zone intrusion, ...) the
summary gives ``events`` out of ``encounters``, the ``rate``, the two-sided 95 % Clopper–Pearson
interval ``ci95`` and the one-sided 95 % upper bound ``upper95``: the rate is below it with 95 %
confidence. With 0 events in n, ``upper95 = 1 - 0.05**(1/n)``, about 3/n (the "rule of three");
the summary's ``collision_rate_upper95`` is this bound for collisions.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from vo3d_opt.extras import needs

if TYPE_CHECKING:
    import pandas as pd

CONFIDENCE = 0.95


def clopper_pearson(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Two-sided exact interval for a binomial proportion with ``k`` events in ``n`` trials."""
    from scipy.stats import beta  # late: scipy.stats takes a second to import

    _check(k, n)
    alpha = 1.0 - confidence
    lo = 0.0 if k == 0 else float(beta.ppf(alpha / 2.0, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1.0 - alpha / 2.0, k + 1, n - k))
    return lo, hi


def upper_bound(k: int, n: int, confidence: float = CONFIDENCE) -> float:
    """One-sided exact upper confidence bound (``P(rate <= bound) >= confidence``)."""
    from scipy.stats import beta

    _check(k, n)
    return 1.0 if k == n else float(beta.ppf(confidence, k + 1, n - k))


def _check(k: int, n: int) -> None:
    if n < 1 or not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n and n >= 1, got k={k}, n={n}")


def event_rate(k: int, n: int) -> dict[str, Any]:
    """``{events, encounters, rate, ci95: [lo, hi], upper95}`` (rate and bounds None if n = 0)."""
    if n == 0:
        return {"events": int(k), "encounters": 0, "rate": None, "ci95": None, "upper95": None}
    lo, hi = clopper_pearson(k, n)
    return {
        "events": int(k),
        "encounters": int(n),
        "rate": k / n,
        "ci95": [lo, hi],
        "upper95": upper_bound(k, n),
    }


def _total(df: pd.DataFrame, col: str) -> int:
    return int(df[col].fillna(0).sum()) if col in df else 0


def _count(mask: pd.Series) -> int:
    return int(mask.fillna(False).astype(bool).sum())


def _min(df: pd.DataFrame, col: str) -> float | None:
    if col not in df or df[col].isna().all():
        return None
    value = float(df[col].min())
    return value if math.isfinite(value) else None


def aggregate(
    df: pd.DataFrame, *, family: str, seed: int, method: str, formulation: str, solver: str
) -> dict[str, Any]:
    """The sweep's summary from its rows (one per encounter, ``error`` None when it ran).

    The sweep's own keys: ``collisions``, ``pz_intrusions`` (vehicle pairs plus vehicle–obstacle
    pairs, i.e. the run summary's ``pz_intrusions`` plus ``obstacle_pz_intrusions``),
    ``not_arrived`` (agents), ``limit_violations`` (altitude plus speed) summed over the encounters
    that ran, ``encounters_with_collision`` / ``_intrusion`` and ``collision_rate_upper95``.
    Encounters that raised are listed under ``errors`` and left out of every count and rate but
    ``rates.error``.
    """
    with needs("sweep", "sweep statistics"):
        import pandas as pd

    ok = df[df["error"].isna()] if "error" in df else df
    n_ok = len(ok)

    def col(name: str) -> pd.Series:
        return ok[name].fillna(0) if name in ok else pd.Series(0, index=ok.index)

    intrusions = col("pz_intrusions") + col("obstacle_pz_intrusions")
    limits = col("altitude_violations") + col("speed_violations")
    events = {
        "collision": _count(col("collisions") > 0),
        "intrusion": _count(intrusions > 0),
        "not_all_arrived": _count(col("reached") < col("agents")),
        "limit_violation": _count(limits > 0),
    }
    # RVO2 does not report infeasible decisions: its fallbacks are unknown, not 0.
    known = ok["fallbacks"].notna() if "fallbacks" in ok else pd.Series(False, index=ok.index)
    fallbacks = int(ok.loc[known, "fallbacks"].sum()) if known.any() else None
    errors = df[df["error"].notna()] if "error" in df else df.iloc[:0]
    rates = {k: event_rate(v, n_ok) for k, v in events.items()}
    if fallbacks is not None:
        rates["fallback"] = event_rate(_count(ok.loc[known, "fallbacks"] > 0), int(known.sum()))
    rates["error"] = event_rate(len(errors), len(df))
    return {
        "family": family,
        "encounters": len(df),
        "seed": seed,
        "method": method,
        "formulation": formulation,
        "solver": solver,
        "completed": n_ok,
        "collisions": _total(ok, "collisions"),
        "encounters_with_collision": events["collision"],
        "pz_intrusions": int(intrusions.sum()),
        "encounters_with_intrusion": events["intrusion"],
        "vehicle_pz_intrusions": _total(ok, "pz_intrusions"),
        "obstacle_pz_intrusions": _total(ok, "obstacle_pz_intrusions"),
        "starts_inside_pz": _total(ok, "starts_inside_pz"),
        "agents": _total(ok, "agents"),
        "not_arrived": int((col("agents") - col("reached")).sum()),
        "encounters_not_all_arrived": events["not_all_arrived"],
        "limit_violations": int(limits.sum()),
        "fallbacks": fallbacks,
        "decisions": _total(ok, "decisions"),
        "collision_rate_upper95": rates["collision"]["upper95"],
        "rates": rates,
        "min_vehicle_distance": _min(ok, "min_vehicle_distance"),
        "min_normalised_distance": _min(ok, "min_normalised_distance"),
        "min_obstacle_distance": _min(ok, "min_obstacle_distance"),
        "errors": [
            {"index": int(i), "error": str(e)}
            for i, e in zip(errors["index"], errors["error"], strict=False)
        ],
    }


#: The events whose rates risk ratios compare (``rates`` keys of the summary).
RATIO_EVENTS = ("collision", "intrusion")


def risk_ratio(k: int, n: int, k_none: int, n_none: int) -> dict[str, Any]:
    """The ratio of a method's event rate ``k / n`` to the rate ``k_none / n_none`` of the
    same encounters flown without avoidance, with Koopman's score interval for a ratio of two
    binomial proportions (statsmodels ``confint_proportions_2indep``, ``method="score"``
    without the Miettinen–Nurminen correction): ``ci95`` two-sided 95 %, ``upper95`` the
    one-sided 95 % upper bound. ``ratio`` and the bounds are None when the encounters without
    avoidance had no event (nothing to reduce).

    Why this interval: it stays defined when the method has no event at all (ratio 0, a finite
    upper bound), the usual case for a good method, where the Katz log interval is not; and the
    two samples are the same encounters, so their outcomes are positively correlated and an
    interval for independent samples is the conservative (wider) one."""
    _check(k, n)
    _check(k_none, n_none)
    out: dict[str, Any] = {
        "events": int(k),
        "encounters": int(n),
        "events_without_avoidance": int(k_none),
        "encounters_without_avoidance": int(n_none),
        "ratio": None,
        "ci95": None,
        "upper95": None,
        "interval": "Koopman score (statsmodels confint_proportions_2indep, method=score)",
    }
    if k_none == 0:
        return out
    lo, hi = _koopman(k, n, k_none, n_none, 1.0 - CONFIDENCE)
    out.update(
        ratio=(k / n) / (k_none / n_none),
        ci95=[lo, hi],
        upper95=_koopman(k, n, k_none, n_none, 2.0 * (1.0 - CONFIDENCE))[1],
    )
    return out


def _koopman(k: int, n: int, k0: int, n0: int, alpha: float) -> tuple[float, float]:
    import numpy as np

    with needs("sweep", "sweep statistics"):
        from statsmodels.stats.proportion import confint_proportions_2indep

    lo, hi = confint_proportions_2indep(
        k, n, k0, n0, method="score", compare="ratio", alpha=alpha, correction=False
    )
    lo, hi = float(np.real(lo)), float(np.real(hi))
    if k == 0 or not math.isfinite(lo):  # the score equation's root at 0, to rounding
        lo = 0.0
    return max(lo, 0.0), hi


def risk_ratios(summary: dict[str, Any], without: dict[str, Any]) -> dict[str, Any]:
    """Each of :data:`RATIO_EVENTS`' :func:`risk_ratio` of a sweep's ``summary`` against the
    summary ``without`` of the same encounters flown with ``--method none``; ``ValueError``
    naming the key when ``without`` is not that (another family, seed or count, or a method
    other than none)."""
    if without.get("method") != "none":
        raise ValueError(f"method: {without.get('method')!r}, not 'none'")
    for key in ("family", "seed", "encounters"):
        if without.get(key) != summary.get(key):
            raise ValueError(f"{key}: {without.get(key)!r} there, {summary.get(key)!r} here")
    out: dict[str, Any] = {}
    for event in RATIO_EVENTS:
        mine, theirs = summary["rates"][event], without["rates"][event]
        out[event] = risk_ratio(
            mine["events"], mine["encounters"], theirs["events"], theirs["encounters"]
        )
    return out
