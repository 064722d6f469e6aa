"""The parameters files a node is started with, and the overrides no parameter takes.

rclpy ignores an override (``--params-file`` entry or ``-p name:=value``) for a parameter the
node never declares, unless the node allows undeclared parameters: a misspelt key in
``config/<node>.params.yaml`` would leave the node on its default without a word.
:class:`~dampest_ros.ros.common.ParamNode` compares the overrides with what it declared and
raises :class:`UnknownParameterError`; :func:`params_files` reads the files of the command
line (duplicate keys refused, lines kept) so that the error names the file and line
(:meth:`UnknownParameterError.located`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the readers (numpy, jsonschema) load only when a file is given
    from dampest_ros.io.strict_yaml import YamlDoc


class UnknownParameterError(ValueError):
    """An override for a parameter the node does not have.

    Parameters
    ----------
    name : str
        The unknown parameter.
    known : sequence of str
        The node's parameters.
    node : str
        The node's name.
    """

    def __init__(self, name: str, known: Sequence[str], node: str) -> None:
        from dampest_ros.io.schema import closest

        self.name, self.known, self.node = name, list(known), node
        self.reason = (f"unknown parameter of {node}{closest(name, self.known)} (its "
                       f"parameters: {', '.join(self.known)}; `{node} --help` describes them)")
        super().__init__(f"{name}: {self.reason}")

    def located(self, files: Sequence[YamlDoc]) -> ValueError:
        """This error with where the override was given: the file and line of the first
        parameters file that has it, else the command line (``-p``)."""
        from dampest_ros.io.strict_yaml import InputError

        for doc in files:
            for path, line in doc.lines.items():
                if len(path) > 2 and path[1] == "ros__parameters" \
                        and ".".join(map(str, path[2:])) == self.name:
                    return InputError(doc.source, line, self.name, self.reason)
        return ValueError(f"-p {self.name}:=...: {self.reason}")


def params_files(argv: Sequence[str]) -> list[YamlDoc]:
    """The ``--params-file`` files of a node's command line, read (duplicate keys refused).

    Raises
    ------
    InputError
        A file that is not valid YAML or has a key twice (file and lines named).
    """
    from dampest_ros.io.strict_yaml import load_yaml

    paths = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--params-file"]
    docs = []
    for path in paths:
        try:
            docs.append(load_yaml(path))
        except OSError:  # rcl names a file it cannot read
            continue
    return docs
