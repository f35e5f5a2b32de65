"""Exact conversion of textual timestamps to int64 nanoseconds.

Parsing "1403715273.262142976" through float64 would lose ~100 ns at epoch times, so decimal
strings are split at the point and converted with integer arithmetic.  Scientific notation
("1.4036e+09", written by some tools) can only be as exact as the text, so it goes through float.
"""
from __future__ import annotations

import numpy as np

#: int64 nanoseconds reach 9.22e18 (year 2262); stamps beyond this are refused, not wrapped around.
_MAX_ABS_NS = 9.0e18


def decimal_strings_to_ns(tokens, unit_scale_ns: int) -> np.ndarray:
    """Convert decimal strings in a unit worth ``unit_scale_ns`` ns (1e9 for seconds, 1 for ns).

    Returns int64 ns; rounds to the nearest nanosecond.  Raises ``ValueError`` on non-numbers,
    non-finite values and stamps outside int64 nanoseconds (never a wrapped-around number).
    """
    tokens = np.asarray(tokens, dtype=str).reshape(-1)
    out = np.empty(len(tokens), dtype=np.int64)
    if len(tokens) == 0:
        return out
    with np.errstate(all="ignore"):
        approx = tokens.astype(np.float64) * unit_scale_ns  # ValueError on a non-number
    if not np.isfinite(approx).all() or (np.abs(approx) > _MAX_ABS_NS).any():
        raise ValueError("timestamp is not finite or outside the int64 nanosecond range")
    lowered = np.char.lower(tokens)
    sci = (np.char.find(lowered, "e") >= 0) | (np.char.find(lowered, "_") >= 0)
    if sci.any():
        out[sci] = np.rint(approx[sci]).astype(np.int64)
    plain = ~sci
    if plain.any():
        parts = np.char.partition(tokens[plain], ".")
        whole, frac = parts[:, 0], parts[:, 2]
        neg = np.char.startswith(whole, "-")
        whole_abs = np.char.lstrip(whole, "+-")
        whole_abs = np.where(whole_abs == "", "0", whole_abs)
        digits = len(str(unit_scale_ns)) - 1  # decimal digits that still map to whole ns
        frac_kept = np.char.ljust(np.char.rstrip(np.char.ljust(frac, digits, "0")), digits, "0")
        head = np.array([f[:digits] if digits else "" for f in frac_kept.tolist()]) if digits else None
        ns = whole_abs.astype(np.int64) * unit_scale_ns
        if digits:
            ns = ns + head.astype(np.int64)
            # round half up on the first dropped digit
            rest = np.array([f[digits:digits + 1] for f in frac.tolist()])
            ns = ns + ((rest != "") & (rest >= "5")).astype(np.int64)
        elif (frac != "").any():
            ns = ns + (np.char.ljust(frac, 1, "0").astype("U1") >= "5").astype(np.int64)
        out[plain] = np.where(neg, -ns, ns)
    return out


def ns_to_seconds_strings(t_ns: np.ndarray) -> list[str]:
    """Format int64 ns as exact decimal seconds with 9 fractional digits (never rounded)."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    sec, frac = np.divmod(t_ns, 1_000_000_000)
    return [f"{s}.{f:09d}" for s, f in zip(sec.tolist(), frac.tolist())]
