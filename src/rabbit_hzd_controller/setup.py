"""ament_python package rabbit_hzd_controller: ``colcon build`` on a ROS 2 install, ``pip install -e`` in .venv."""

from setuptools import find_packages, setup

PACKAGE = "rabbit_hzd_controller"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="rabbit-hzd maintainers",
    maintainer_email="maintainers@rabbit-hzd.invalid",
    description="Hybrid Zero Dynamics PD controller for RABBIT: Bezier virtual constraints, phase, stance switching.",
    license="Apache-2.0",
    entry_points={"console_scripts": ["hzd_controller_node = rabbit_hzd_controller.hzd_controller_node:main"]},
)
