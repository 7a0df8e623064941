"""Batch evaluation (``cold-eval``): the scenarios and plan per map (``scenarios``), the
frame-by-frame loop (``evaluator``) filling a ``collector``, the reports (``report``),
plots (``plots``), the paper preset (``paper``) and one whole run with its output folder
(``run``)."""
