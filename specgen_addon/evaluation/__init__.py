"""The paper's evaluation (§4) on held-out corpus materials and real RGL files.

``baselines`` (per-pixel RGB → spectrum uplifting), ``protocol`` (materials, scenes, shapes),
``tables`` (tables (a)–(e) and the real-data check, resumable), ``plots`` and ``ablation``
(equal-budget training arms). ``python -m specgen_addon paper-tables`` runs it all.
"""
