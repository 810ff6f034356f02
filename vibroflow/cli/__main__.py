"""`python -m vibroflow.cli`: the `vibroflow` command."""
from vibroflow.cli import main

main()
