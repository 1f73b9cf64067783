"""ament_python package rabbit_sim: ``colcon build`` on a ROS 2 install, ``pip install -e`` in .venv."""

from setuptools import find_packages, setup

PACKAGE = "rabbit_sim"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={'rabbit_sim': ['models/*.xml', 'urdf/*.urdf']},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        ("share/" + PACKAGE + "/urdf", ["rabbit_sim/urdf/rabbit.urdf"]),  # robot_state_publisher, RViz
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="rabbit-hzd maintainers",
    maintainer_email="maintainers@rabbit-hzd.invalid",
    description="MuJoCo model of the RABBIT biped and its simulator node.",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "sim_node = rabbit_sim.sim_node:main",
        "recorder_node = rabbit_sim.recorder_node:main",
    ]},
)
