"""One-road OpenDRIVE maps for the camera sensor's visibility rules (issue 26): a reference
line that is a line or an arc, an optional elevation parabola, right-hand lanes with
chosen types, widths and ``<roadMark>`` records. Lengths and positions have closed forms.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Final

LANE_WIDTH_M: Final[float] = 3.5


@dataclass(frozen=True)
class Lane:
    """One lane: id, type, width (m) and its outer border's marks as (sOffset m, type)."""

    id: int
    type: str = "driving"
    width_m: float = LANE_WIDTH_M
    marks: tuple[tuple[float, str], ...] = ((0.0, "solid"),)

    def xml(self) -> str:
        marks = "".join(f'<roadMark sOffset="{s!r}" type="{kind}" weight="standard" color="standard" width="0.12"/>'
                        for s, kind in self.marks)
        return (f'<lane id="{self.id}" type="{self.type}" level="false"><link/>'
                f'<width sOffset="0.0" a="{self.width_m!r}" b="0.0" c="0.0" d="0.0"/>{marks}</lane>')


def one_road(length_m: float, lanes: tuple[Lane, ...], *, curvature: float = 0.0, elevation_c: float = 0.0,
             junction: str = "-1", centre_mark: str = "solid") -> str:
    """One road along +x from the origin (an arc of ``curvature`` 1/m, counter-clockwise,
    when not 0) of ``length_m``; elevation z(s) = ``elevation_c``·s² (m); ``lanes`` right
    of the reference line (ids < 0) and left of it (ids > 0); the centre line marked
    ``centre_mark``."""
    shape = "<line/>" if curvature == 0.0 else f'<arc curvature="{curvature!r}"/>'
    left = "".join(lane.xml() for lane in sorted((lane for lane in lanes if lane.id > 0), key=lambda lane: -lane.id))
    right = "".join(lane.xml() for lane in sorted((lane for lane in lanes if lane.id < 0), key=lambda lane: -lane.id))
    centre = f'<lane id="0" type="none" level="false"><link/><roadMark sOffset="0.0" type="{centre_mark}"/></lane>'
    sides = (f"<left>{left}</left>" if left else "") + f"<center>{centre}</center>"
    sides += f"<right>{right}</right>" if right else ""
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<OpenDRIVE>'
            '<header revMajor="1" revMinor="6" name="camera" vendor="cold-maps tests"/>'
            f'<road id="1" length="{length_m!r}" junction="{junction}" rule="RHT"><link/>'
            f'<planView><geometry s="0.0" x="0.0" y="0.0" hdg="0.0" length="{length_m!r}">{shape}</geometry>'
            f'</planView><elevationProfile><elevation s="0.0" a="0.0" b="0.0" c="{elevation_c!r}" d="0.0"/>'
            f'</elevationProfile><lanes><laneSection s="0.0">{sides}</laneSection></lanes></road>'
            + (f'<junction id="{junction}" name="j"/>' if junction != "-1" else "") + "</OpenDRIVE>\n")


def write(folder: Path, name: str, text: str) -> Path:
    """Writes ``text`` as ``folder/name.xodr``; returns the path."""
    path = folder / f"{name}.xodr"
    path.write_text(text, encoding="utf-8")
    return path
