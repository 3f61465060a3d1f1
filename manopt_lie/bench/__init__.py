"""The benchmark harness the command line runs (``manopt-lie bench``, ``demo``).

Suites, records, reports, figures, peers and timing. Not a stable API: it imports the
applications (``manopt_lie.problems``) and the core, and only ``manopt_lie.cli`` imports it.
"""
