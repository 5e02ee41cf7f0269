"""``python -m tests.tools``: install every test tool (see :mod:`tests.tools`)."""

from tests.tools import TOOLS, install

for tool in TOOLS:
    print(f"{tool}: {install(tool)}")
