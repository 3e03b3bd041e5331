"""wxsky's tools, one folder per purpose (tools/README.md lists every tool).

A package so that tools import each other as `tools.<folder>.<name>`, whether run as scripts
(`python tools/bench/bench_towers.py`: each puts the checkout's root on sys.path first) or
loaded by the tests (tests/tool_loader.py). Nothing here is installed with wxsky.
"""
