"""Why a UDP bind failed, said in words: an address this machine lacks, a port in use.

The foreign address is in TEST-NET-1 (192.0.2.0/24, RFC 5737), which no machine holds; it is only bound,
never sent to.
"""

from __future__ import annotations

import pytest

from facepuppet.runtime import cli
from facepuppet.runtime.inputs.udp import bind_udp

from helpers.small_characters import sphere_character

NOT_LOCAL = "192.0.2.7"


def test_binding_an_address_this_machine_lacks_says_it_is_not_local():
    with pytest.raises(OSError, match=rf"cannot listen for vmc input on {NOT_LOCAL}:39539: .*"
                                      rf"\({NOT_LOCAL} is not an address of this machine") as info:
        bind_udp(NOT_LOCAL, 39539, "vmc")
    assert "another program" not in str(info.value)


def test_a_port_in_use_says_so():
    first, _ = bind_udp("127.0.0.1", 0, "vmc")
    try:
        port = first.getsockname()[1]
        with pytest.raises(OSError, match=r"another program, or a previous run, is using this port") as info:
            bind_udp("127.0.0.1", port, "vmc")
        assert "not an address of this machine" not in str(info.value)
    finally:
        first.close()


@pytest.mark.parametrize("receiver", ["thread", "process"])
def test_run_with_a_foreign_listen_address_exits_2_with_the_reason(tmp_path, capsys, receiver):
    character = sphere_character().save(tmp_path / "sphere.npz")
    rc = cli.main(["run", "-c", str(character), "--input", "vmc", "--listen", f"{NOT_LOCAL}:39539", "--headless",
                   "--duration", "0.1", "--receiver", receiver])
    assert rc == 2
    err = capsys.readouterr().err
    assert f"{NOT_LOCAL} is not an address of this machine" in err and "Traceback" not in err
