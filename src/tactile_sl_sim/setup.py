"""ament_python package: the simulator of the tactile-sl sensor and its sim_camera node."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "tactile_sl_sim"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
        (f"share/{PACKAGE}/artwork", glob("artwork/*")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="tactile-sl developers",
    maintainer_email="dev@tactile-sl.invalid",
    description="Simulator of the tactile-sl sensor (images with ground truth)",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "sim_camera = tactile_sl_sim.nodes.sim_camera_node:main",
        ],
    },
)
