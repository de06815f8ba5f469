"""The metric definitions: pure functions over arrays and tables, each with its source
(docs/metrics.md). Signals and their statistics (:mod:`.signals`), formation keeping
(:mod:`.formation`, :mod:`.platoon`, :mod:`.propagation`), comfort (:mod:`.comfort`,
:mod:`.iso2631`, :mod:`.iso2631_weighting`, :mod:`.limits`), communication (:mod:`.comm`),
maneuvers and hand-overs (:mod:`.maneuvers`, :mod:`.handover`), traffic interaction
(:mod:`.traffic` with :mod:`.footprint`, :mod:`.pair_geometry`, :mod:`.ssm`,
:mod:`.travel_time`; :mod:`.conflicts`). Nothing here reads a file or imports another part of
the analysis.
"""
