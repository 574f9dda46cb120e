"""The test kit: machinery the tests and the benches share, kept out of the product.

The fault matrix, the crash trials and the fuzzing need things no station should
carry: an inspection session held open in a thread across many test cells, a fault
injector, a child program to SIGKILL, fake transports that answer garbage. They live
here, beside the product rather than in it:

* ``testkit.session``  -- :class:`SessionThread`, an inspection session on the twins in
  a loop of its own (``station.loopthread``), shared by a kind's matrix cells;
* ``testkit.cells``    -- the matrix's cells (fault kind, phase, duration) and what each
  must end as;
* ``testkit.injector`` -- :class:`Injector`: a cell's fault switched on and off through
  the engine's public seams (message hooks, events) and the store's;
* ``testkit.matrix``   -- :func:`run_cell` and its :class:`CellResult`;
* ``testkit.crash``    -- SIGKILL trials of ``python -m testkit.crash_child`` and the
  store check after each kill;
* ``testkit.fuzz``     -- the fuzz targets, their seeds and strategies, with the fake
  serial port and Modbus client of ``testkit.fakes``.

Who may import it (docs/reliability.md): ``tests/`` and the benches
(``station/bench/``), as benches may import ``sim``; no other module of the product.
It may import everything (it drives the whole station on the twins).
"""
