"""pytest plugin for ``make test-compat`` (``-p pytest_bpy_exit`` with ``tools`` on the path).

bpy 4.2 and 4.5 *as Python modules* cannot end a process once an add-on property with an update
callback was registered (4.2 crashes, 4.5 hangs in C++ static destructors; see
``engine/blender/compat.py``). After pytest has written its report, this ends the test process
with pytest's exit status through ``compat.exit_process``; with bpy 5.0 it does nothing.
"""
import pytest

_status = 0


def pytest_sessionfinish(session, exitstatus):
    global _status
    _status = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    from lanterna.engine.blender import compat

    if compat.module_exit_is_unsafe():
        compat.exit_process(_status)
