"""Small trace files written into tmp_path, in the public NGSIM / highD / time,speed layouts."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

NGSIM_COLUMNS = (
    "Vehicle_ID,Frame_ID,Total_Frames,Global_Time,Local_X,Local_Y,Global_X,Global_Y,"
    "v_Length,v_Width,v_Class,v_Vel,v_Acc,Lane_ID,Preceding,Following,Space_Headway,"
    "Time_Headway"
)


def ngsim_row(vehicle: int | str, frame: int | str, vel_fps: float | str, lane: int = 2) -> str:
    """One NGSIM row; everything except Vehicle_ID, Frame_ID and v_Vel is plausible filler."""
    global_time = 1113433136100 + 100 * int(frame) if str(frame).isdigit() else 0
    return (
        f"{vehicle},{frame},500,{global_time},16.467,35.381,6451137.641,1873344.962,"
        f"14.5,4.9,2,{vel_fps},0.00,{lane},0,0,0.00,0.00"
    )


@pytest.fixture
def write_text(tmp_path: Path) -> Callable[[str, str], Path]:
    def write(name: str, text: str) -> Path:
        path = tmp_path / name
        path.write_text(text)
        return path

    return write


@pytest.fixture
def write_ngsim(tmp_path: Path) -> Callable[..., Path]:
    """Write ``rows`` (tuples for :func:`ngsim_row` or raw strings) under an NGSIM header."""

    def write(name: str, rows: list, header: str = NGSIM_COLUMNS) -> Path:
        lines = [header] + [r if isinstance(r, str) else ngsim_row(*r) for r in rows]
        path = tmp_path / name
        path.write_text("\n".join(lines) + "\n")
        return path

    return write
