"""The evaluation report ``reports/NAME/index.html``.

The page (:mod:`.page`, template ``templates/report.html``), its tables
(:mod:`.tables`), calibration diagnostics (:mod:`.calibration`), provenance and
the rig (:mod:`.provenance`), figures (:mod:`.figures`), shaded renders
(:mod:`.shaded`), animations (:mod:`.animation`) and the 3D view
(:mod:`.view3d`).
"""
