"""Small nodes following the node convention (docs/tools.md), for the launcher and CLI tests."""
