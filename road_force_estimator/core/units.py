"""Units of what the commands print (``--units si|us``) and the rounding of printed numbers.

``si``: IRI in m/km, distances in metres, 100 m segments by default. ``us``: IRI in in/mi
(1 m/km = 63.36 in/mi exactly: 1 mi = 63 360 in), distances in feet (0.3048 m) and 0.1-mile
(160.9344 m) segments by default. Files for programs (``segments.csv``, Parquet, JSON) stay
in SI, their column names carry the unit.

The rounding follows what the measurement supports: 1 N of load, 1 mm of distance,
0.001 m/km of IRI, 0.1 um of elevation (:data:`DECIMALS`).

Condition bands: FHWA's (Highway Performance Monitoring System) good < 95 in/mi,
fair 95-170 in/mi, poor > 170 in/mi (:data:`CONDITION_BANDS_IN_PER_MI`).

This module imports nothing but the standard library (core).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

__all__ = ['IN_PER_MI_PER_M_PER_KM', 'M_PER_FT', 'M_PER_MILE', 'UNIT_SYSTEMS', 'DECIMALS',
           'CONDITION_BANDS_IN_PER_MI', 'Units', 'units', 'rounded', 'condition_bands']

#: 1 m/km in in/mi: 1 mi = 63 360 in, so 1 m/km = 1 mm/m = 63 360 in / 1 000 000 in x 1000.
IN_PER_MI_PER_M_PER_KM = 63.36
#: The international foot (m).
M_PER_FT = 0.3048
#: The international mile (m).
M_PER_MILE = 1609.344
#: The unit systems of ``--units``.
UNIT_SYSTEMS = ('si', 'us')
#: Decimals of printed numbers: load (N), distance (m), IRI (m/km), elevation (m).
DECIMALS = {'load_n': 0, 'distance_m': 3, 'iri_m_per_km': 3, 'elevation_m': 7,
            'ltr': 4, 'dlc': 4, 'degrees': 7}
#: FHWA condition bands of IRI (in/mi): good below the first, poor above the second.
CONDITION_BANDS_IN_PER_MI = (95.0, 170.0)


@dataclass(frozen=True)
class Units:
    """One unit system of the printed numbers.

    Attributes
    ----------
    name : 'si' or 'us'
    iri_unit, length_unit : str
        ``'m/km'``/``'in/mi'`` and ``'m'``/``'ft'``.
    iri_per_m_per_km : float
        The printed IRI of 1 m/km (1 or 63.36).
    length_per_m : float
        The printed length of 1 m (1 or 1 / 0.3048).
    segment_length_m : float
        Default segment length (m): 100 or 160.9344 (0.1 mi).
    iri_decimals, length_decimals : int
        Printed decimals: 0.001 m/km (0.01 in/mi) and 1 mm (0.001 ft).
    """

    name: str
    iri_unit: str
    length_unit: str
    iri_per_m_per_km: float
    length_per_m: float
    segment_length_m: float
    iri_decimals: int
    length_decimals: int

    def iri(self, m_per_km: float) -> float:
        """IRI (m/km) in these units."""
        return float(m_per_km) * self.iri_per_m_per_km

    def length(self, m: float) -> float:
        """A length (m) in these units."""
        return float(m) * self.length_per_m

    def iri_text(self, m_per_km: float | None) -> str:
        """IRI rounded in these units (``n/a`` when unknown), without the unit."""
        return _text(None if m_per_km is None else self.iri(m_per_km), self.iri_decimals)

    def length_text(self, m: float | None, decimals: int | None = None) -> str:
        """A length rounded in these units (``n/a`` when unknown), without the unit."""
        d = self.length_decimals if decimals is None else decimals
        return _text(None if m is None else self.length(m), d)

    def segment_text(self, segment_length_m: float) -> str:
        """``100 m`` or ``0.1 mi (528 ft)``: a segment length as a road engineer says it."""
        if self.name == 'us':
            miles = segment_length_m / M_PER_MILE
            return f'{miles:.4g} mi ({self.length(segment_length_m):.5g} ft)'
        return f'{segment_length_m:.6g} m'


_SYSTEMS = {
    'si': Units('si', 'm/km', 'm', 1.0, 1.0, 100.0, 3, 3),
    'us': Units('us', 'in/mi', 'ft', IN_PER_MI_PER_M_PER_KM, 1.0 / M_PER_FT,
                0.1 * M_PER_MILE, 2, 3),
}


def units(name: str = 'si') -> Units:
    """The :class:`Units` of ``'si'`` or ``'us'``.

    Raises
    ------
    ValueError
        Another name.
    """
    try:
        return _SYSTEMS[name]
    except KeyError:
        raise ValueError(f'units {name!r}: one of {", ".join(UNIT_SYSTEMS)}') from None


def _text(value: float | None, decimals: int) -> str:
    if value is None or math.isnan(value):
        return 'n/a'
    if math.isinf(value):
        return 'inf' if value > 0 else '-inf'
    text = f'{value:.{decimals}f}'
    return text[1:] if text.startswith('-') and float(text) == 0.0 else text


def rounded(value: float, kind: str) -> str:
    """``value`` printed with the decimals of :data:`DECIMALS` ``[kind]`` (``nan`` if
    unknown, no ``-0``)."""
    text = _text(float(value), DECIMALS[kind])
    return 'nan' if text == 'n/a' else text


def condition_bands(u: Units) -> tuple[float, float]:
    """FHWA's good / poor limits (:data:`CONDITION_BANDS_IN_PER_MI`) in the units ``u``."""
    lo, hi = CONDITION_BANDS_IN_PER_MI
    return (lo / IN_PER_MI_PER_M_PER_KM * u.iri_per_m_per_km,
            hi / IN_PER_MI_PER_M_PER_KM * u.iri_per_m_per_km)
