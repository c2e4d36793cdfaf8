"""Helpers shared by test files in tests/unit and tests/workflow (tests/ is on the import path
through pytest's ``pythonpath`` option: ``from helpers.clouds import targets``)."""
