"""ament_python package: image sources (stereo cameras, bag replay)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "tactile_sl_camera"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="tactile-sl developers",
    maintainer_email="dev@tactile-sl.invalid",
    description="Image sources for the tactile-sl sensor",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "replay = tactile_sl_camera.nodes.replay_node:main",
            "stereo_camera = tactile_sl_camera.nodes.stereo_camera_node:main",
        ],
    },
)
