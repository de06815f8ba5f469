"""report.html of a road run no formation entered (analysis/runs/traffic_only.py): its status,
why the formation metrics are absent, and the traffic's measures."""
from __future__ import annotations

import html
from typing import Any


def traffic_only_report(name: str, doc: dict[str, Any]) -> str:
    """The HTML page for ``doc`` (traffic_only_doc's metrics.json) of run ``name``."""
    run, tr = doc["run"], doc["traffic"]["run"]
    units = doc["traffic"].get("units") or {}
    rows = "".join(f"<tr><td>{html.escape(str(k))}</td><td>{'&ndash;' if v is None else html.escape(f'{v:.6g}' if isinstance(v, float) else str(v))}</td>"
                   f"<td>{html.escape(units.get(k, ''))}</td></tr>" for k, v in tr.items()
                   if not isinstance(v, (dict, list)))
    flows = run.get("formation_flows") or {}
    asked = "; ".join(f"formation flow {k}: {c.get('inserted')} of {c.get('requested')} formations inserted"
                      for k, c in flows.items())
    return ("<!doctype html><html><head><meta charset='utf-8'><title>Run "
            f"{html.escape(name)}</title></head><body><h1>Formation run analysis: {html.escape(name)}</h1>"
            f"<p>status: <b>{html.escape(str(run.get('status')))}</b></p>"
            f"<div id=\"summary\"><h2>Summary</h2><ul><li>{html.escape(run['formation_metrics'])}"
            + (f" ({html.escape(asked)})" if asked else "") + "</li>"
            "<li>no safety incident: no formation vehicle on the road</li></ul></div>"
            "<h2>Traffic (measurement sections)</h2><table><tr><th>metric</th><th>value</th>"
            f"<th>unit</th></tr>{rows}</table></body></html>")
