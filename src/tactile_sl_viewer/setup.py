"""ament_python package: the live browser view of the decoder's outputs."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "tactile_sl_viewer"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={PACKAGE: ["static/*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="tactile-sl developers",
    maintainer_email="dev@tactile-sl.invalid",
    description="Live browser view of the tactile-sl decoder's outputs",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "viewer = tactile_sl_viewer.nodes.viewer_node:main",
        ],
    },
)
