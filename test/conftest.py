"""Every test runs on a private, loopback-only ROS graph (set before rclpy is imported)."""
import os
from pathlib import Path
import random
import tempfile

_ROS_TMP = Path(tempfile.mkdtemp(prefix='qjt_test_ros_'))
os.environ.update({
    'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
    'ROS_DOMAIN_ID': os.environ.get('QJT_TEST_DOMAIN_ID', str(random.randint(1, 100))),
    'ROS_HOME': str(_ROS_TMP),
    'ROS_LOG_DIR': str(_ROS_TMP / 'log'),
})
os.environ.pop('ROS_STATIC_PEERS', None)
