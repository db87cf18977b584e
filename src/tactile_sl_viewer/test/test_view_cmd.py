"""`tactile-sl view` is a command of the CLI, with its cap on the frames sent to a page."""
from tactile_sl_decoder.cli import build_parser
from tactile_sl_viewer import view_cmd


def test_view_is_a_tactile_sl_command_and_takes_max_rate():
    parser = build_parser("view")
    args = parser.parse_args(["view", "bag.mcap", "--max-rate", "5"])
    assert args.func is view_cmd.run and args.max_rate == 5.0
    assert parser.parse_args(["view", "bag.mcap"]).max_rate == 0.0   # bags: no cap


def test_a_negative_max_rate_is_refused(capsys):
    args = build_parser("view").parse_args(["view", "bag.mcap", "--max-rate", "-1"])
    assert view_cmd.run(args) == 1
    assert "--max-rate" in capsys.readouterr().err
