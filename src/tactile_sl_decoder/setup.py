"""ament_python package: pattern encoder, glyph extraction/classification, decoding, 3-D."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "tactile_sl_decoder"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={PACKAGE: ["data/*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
        (f"share/{PACKAGE}/rviz", glob("rviz/*.rviz")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="tactile-sl developers",
    maintainer_email="dev@tactile-sl.invalid",
    description="tactile-sl pipeline: pattern, extraction, classification, decoding, 3-D",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "tactile-sl = tactile_sl_decoder.cli:main",
            "symbol_extractor = tactile_sl_decoder.nodes.symbol_extractor_node:main",
            "symbol_classifier = tactile_sl_decoder.nodes.symbol_classifier_node:main",
            "decoder = tactile_sl_decoder.nodes.decoder_node:main",
        ],
    },
)
