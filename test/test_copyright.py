"""
The ament_python template's copyright test, skipped as the template ships it.

ament_copyright is not on PyPI (it runs in a ROS 2 installation), and the sources carry no
per-file header: the license is the package's LICENSE file, checked by test_package.py.
"""

import pytest


@pytest.mark.skip(reason='No copyright header has been placed in the source files')
@pytest.mark.copyright
@pytest.mark.linter
def test_copyright():
    from ament_copyright.main import main

    rc = main(argv=['.', 'test'])
    assert rc == 0, 'Found errors'
