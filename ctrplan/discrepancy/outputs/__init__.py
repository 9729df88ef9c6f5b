"""Stage 9 of the discrepancy workflow: what it writes.

- :mod:`.output`: the test split's figures and the updated robot file;
- :mod:`.results`: ``results.json`` (plain JSON of the typed results);
- :mod:`.report`: the report folder (markdown from ``results.json`` alone, plots), the only
  module that converts results to millimetres and degrees; :mod:`.logtext`: figures in log lines.
"""
