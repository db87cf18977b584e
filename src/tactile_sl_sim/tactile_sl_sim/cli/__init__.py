"""`tactile-sl` subcommands of the simulator package (registered by tactile_sl_decoder.cli)."""
