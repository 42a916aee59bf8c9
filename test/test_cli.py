"""The ``lili-odom`` command table names only commands that exist."""
import importlib

import pytest

from lili_odom.cli import COMMANDS, build_parser


@pytest.mark.parametrize("name", COMMANDS)
def test_every_listed_command_has_its_module(name):
    module = importlib.import_module(f"lili_odom.commands.{name}")
    assert module.help and callable(module.add_arguments) and callable(module.run)


def test_the_parser_offers_exactly_the_listed_commands():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert sorted(sub.choices) == sorted(COMMANDS)
