"""The top floor: the command registry, results folders, sweeps and one module per command. Only this
package (and the CLI) writes files or knows about commands; the algorithm packages below return result objects."""
