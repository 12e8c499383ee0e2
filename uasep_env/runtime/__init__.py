"""Files and processes handled safely: what the package needs from the machine it runs on.

* :mod:`~uasep_env.runtime.atomic` -- outputs written atomically, never over another run's.
* :mod:`~uasep_env.runtime.jsonio` -- the one JSON writer and the bounded JSON reader.
* :mod:`~uasep_env.runtime.boundedzip` -- zip archives read within limits (no zip bombs).
* :mod:`~uasep_env.runtime.runlock` -- one process per output folder.
* :mod:`~uasep_env.runtime.tables` -- the one text-table renderer.
* :mod:`~uasep_env.runtime.cores` -- the threads and processes a run may use.
* :mod:`~uasep_env.runtime.capacity` -- memory budgets checked before allocating.

Nothing here imports the simulation, the environments or the policies.
"""
