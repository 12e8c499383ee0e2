"""Reports a new method is published with (``uasep-report``): scaling and held-out tables.

:mod:`~uasep_env.reporting.scaling` plays the sweeps (formation sizes, obstacle counts, the
held-out bank), :mod:`~uasep_env.reporting.scaling_views` writes their tables and figure
(matplotlib imported only for the figure).
"""
