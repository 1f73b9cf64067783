"""ament_python package rabbit_policy: ``colcon build`` on a ROS 2 install, ``pip install -e`` in .venv."""

from setuptools import find_packages, setup

PACKAGE = "rabbit_policy"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={'rabbit_policy': ['gaits/*.json', 'controllers/*.yaml', 'controllers/*.npz',
                                   'trained/*.md', 'trained/*.json']},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="rabbit-hzd maintainers",
    maintainer_email="maintainers@rabbit-hzd.invalid",
    description="Gait policies for RABBIT: the classic HZD gait library and the learned HZD-RL policy.",
    license="Apache-2.0",
    entry_points={"console_scripts": ["policy_node = rabbit_policy.policy_node:main",
                                      "walk = rabbit_policy.commands.walk:main",
                                      "run_stack = rabbit_policy.commands.run_stack:main",
                                      "set_speed = rabbit_policy.commands.set_speed:main"]},
)
