"""The Eulerian landing's choices, in a module that loads no numba, so that the command line
checks `--landing` without compiling anything (tests/test_scenario.py::
test_package_import_is_light).

LANDINGS: where the Eulerian wall cells' landing above the wall row is counted, by the pairs of
cells across each z face (compaction_landing.py) or along each column by the impulse through its
z faces (column_landing.py)."""

LANDINGS = ("pairs", "columns")
