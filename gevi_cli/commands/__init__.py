"""One module per `gevi` subcommand; each defines a click command named ``command``."""
