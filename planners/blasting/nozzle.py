"""Blasting nozzle model (seed §3.2.1, Eq. 3.1, Table 3.1 — Boride T159).

The sand stream is a cone; where it meets the surface it blasts a disc of
radius ``Rc = ds·(dmax − dmin)/(2L) + dmax/2`` (Eq. 3.1) at stream length
``ds``.  The seed keeps ``ds`` between 100 and 500 mm for safety and quality.

Note: Eq. 3.1 with Table 3.1 gives Rc ≈ 15.9 mm for the medium nozzle at
300 mm, while the seed's simulations (§4.2.1) use discs of 0.04 m at 0.3 m;
the planner therefore accepts an explicit disc radius for the seed's scenes.
"""

from __future__ import annotations

from dataclasses import dataclass

from planners.errors import InvalidInputError, StreamLengthError

STREAM_MIN_MM = 100.0
STREAM_MAX_MM = 500.0


@dataclass(frozen=True)
class Nozzle:
    """Boride T159 cone dimensions in millimetres (seed Table 3.1)."""

    name: str
    d_max_mm: float
    d_min_mm: float
    cone_length_mm: float

    def radius_mm(self, stream_length_mm: float) -> float:
        """Blast disc radius Rc in mm at stream length ``ds`` (Eq. 3.1)."""
        ds = check_stream_length(stream_length_mm)
        return (
            ds * (self.d_max_mm - self.d_min_mm) / (2.0 * self.cone_length_mm) + self.d_max_mm / 2.0
        )


# seed Table 3.1
NOZZLES: dict[str, Nozzle] = {
    "small": Nozzle("small", 7.0, 4.5, 75.0),
    "medium": Nozzle("medium", 13.0, 6.0, 112.0),
    "large": Nozzle("large", 15.0, 7.0, 145.0),
}


def check_stream_length(stream_length_mm: float) -> float:
    """The stream length in mm if inside the seed's 100–500 mm window."""
    try:
        ds = float(stream_length_mm)
    except (TypeError, ValueError):
        raise InvalidInputError(
            f"stream_length_mm must be a number, got {stream_length_mm!r}"
        ) from None
    if not (STREAM_MIN_MM <= ds <= STREAM_MAX_MM):
        raise StreamLengthError(
            f"stream_length_mm={ds:g} is outside {STREAM_MIN_MM:g}–{STREAM_MAX_MM:g} mm: shorter "
            "streams are unsafe for the crew and longer ones lose blasting quality (seed §3.2.1)"
        )
    return ds


def get_nozzle(nozzle: str | Nozzle) -> Nozzle:
    """A :class:`Nozzle` from its name (``small``/``medium``/``large``) or itself."""
    if isinstance(nozzle, Nozzle):
        return nozzle
    key = str(nozzle).lower()
    if key not in NOZZLES:
        raise InvalidInputError(f"unknown nozzle {nozzle!r}; choose one of {', '.join(NOZZLES)}")
    return NOZZLES[key]


def blast_radius_m(nozzle: str | Nozzle, stream_length_mm: float) -> float:
    """Disc radius in metres for a nozzle and stream length (Eq. 3.1)."""
    return get_nozzle(nozzle).radius_mm(stream_length_mm) / 1000.0
