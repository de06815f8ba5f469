"""Connecting to SUMO over a socket (the traci backend, sumo-gui, a SUMO to attach to).

Functions of the SUMO adapter (sumo/adapter/__init__.py, the only module that imports
libsumo/traci): ``api`` is the traci module it imported.
"""
from __future__ import annotations

from ..types import GUI_VIEW, GUI_ZOOM, START_TIMEOUT_S, SumoError


def start_socket(api, cmd: list[str]):
    """Start SUMO (``cmd``) as a process and connect within START_TIMEOUT_S; a SUMO that exits
    or never listens is killed and its own message raised (never a hang). Returns (SUMO's
    version, the process)."""
    import contextlib
    import io
    import subprocess
    import tempfile

    import sumolib

    port = sumolib.miscutils.getFreeSocketPort()
    err = tempfile.TemporaryFile()
    proc = subprocess.Popen(cmd + ["--remote-port", str(port)], stdout=err, stderr=err)
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # traci prints every retry
            api.init(port, numRetries=START_TIMEOUT_S, proc=proc)
        version = api.getVersion()[1]
    except Exception as exc:
        if proc.poll() is None:
            proc.kill()
        proc.wait(10)
        err.seek(0)
        said = err.read().decode(errors="replace").strip()
        raise SumoError(f"SUMO did not start ({type(exc).__name__}: {exc})"
                        + (f": {said[-2000:]}" if said else "")) from None
    finally:
        err.close()
    return version, proc


def attach_socket(api, port: int) -> str:
    """Connect to a SUMO started elsewhere with ``--remote-port port``; returns its version."""
    import time

    deadline = time.monotonic() + ATTACH_WAIT_S
    while True:  # quiet tries: traci.init's own retries take a minute and print a line each
        try:
            api.init(port, numRetries=0)
            return api.getVersion()[1]
        except Exception as exc:
            if time.monotonic() > deadline:
                raise SumoError(f"could not attach to SUMO on port {port} within {ATTACH_WAIT_S:g} s "
                                f"(is SUMO running with --remote-port {port}?): {exc}") from None
            time.sleep(0.25)


ATTACH_WAIT_S = 5.0
"""How long an attach waits for SUMO to open its port [s]."""


def follow_view(api, vehicle_id: str) -> None:
    """sumo-gui: keep the view on ``vehicle_id`` (a member), zoomed to the formation."""
    try:
        api.gui.trackVehicle(GUI_VIEW, vehicle_id)
        api.gui.setZoom(GUI_VIEW, GUI_ZOOM)
    except Exception:  # a view without tracking is still a view: never fail the run
        pass
