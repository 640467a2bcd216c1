"""ament_pep257 over the package, as the ros2 pkg create template does."""
from pathlib import Path

from ament_pep257.main import main
import pytest

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    rc = main(argv=[str(REPO)])
    assert rc == 0, 'Found code style errors / warnings'
