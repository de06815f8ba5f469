"""libsumo 1.28 links Arrow 23: the pinned pyarrow gives no warning in either import order,
and Parquet can be written while a libsumo simulation runs."""
import subprocess
import sys
from pathlib import Path

import pytest

NET = Path(__file__).resolve().parents[1] / "sumo_nets" / "straight3.net.xml"
SCRIPT = """
import warnings, sys
warnings.simplefilter("error")
{imports}
import sumolib
libsumo.start([sumolib.checkBinary("sumo"), "-n", r"{net}", "--no-step-log", "true"])
for _ in range(5):
    libsumo.simulationStep()
t = pa.table({{"t": [libsumo.simulation.getTime()]}})
pq.write_table(t, r"{out}")
libsumo.close()
print(pq.read_table(r"{out}").column("t")[0].as_py())
"""


@pytest.mark.parametrize("order", ["pyarrow_first", "libsumo_first"])
def test_no_arrow_warning_and_parquet_while_libsumo_runs(tmp_path, order):
    imports = ("import pyarrow as pa, pyarrow.parquet as pq\nimport libsumo" if order == "pyarrow_first"
               else "import libsumo\nimport pyarrow as pa, pyarrow.parquet as pq")
    out = tmp_path / "x.parquet"
    r = subprocess.run([sys.executable, "-c", SCRIPT.format(imports=imports, net=NET, out=out)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "might be incompatible" not in r.stdout + r.stderr
    assert float(r.stdout.strip().splitlines()[-1]) == pytest.approx(5.0)
