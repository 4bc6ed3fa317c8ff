"""`softplc check` also checks what only the adapters know (here: the Modbus address map)."""

import textwrap

from softplc.app.cli import main


def test_check_reports_an_overlapping_modbus_address_with_its_location(tmp_path, capsys):
    path = tmp_path / "tagdb.yaml"
    path.write_text(textwrap.dedent("""\
        version: 1
        tags:
          a: {type: int16, modbus: {address: 10}}
          b: {type: int32, modbus: {address: 9}}
        servers:
          modbus: {enabled: true, port: 0}
          opcua: {enabled: false}
        """))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:4:" in err and "overlaps 'a'" in err
    assert "Traceback" not in err
