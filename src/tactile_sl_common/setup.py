"""ament_python package: shared formats, bag I/O, safe files, elasticity, node helpers."""
from setuptools import find_packages, setup

PACKAGE = "tactile_sl_common"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="tactile-sl developers",
    maintainer_email="dev@tactile-sl.invalid",
    description="tactile-sl shared formats, bag I/O, safe files, elasticity and node helpers",
    license="Apache-2.0",
)
