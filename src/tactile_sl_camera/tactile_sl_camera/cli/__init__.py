"""`tactile-sl` subcommands of the camera package (registered by tactile_sl_decoder.cli)."""
