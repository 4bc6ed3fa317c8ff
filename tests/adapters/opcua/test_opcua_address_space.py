"""Folder planning: groups become folders, and no folder ever gets more than `folder_size` children."""

from __future__ import annotations

from asyncua import ua

from softplc.adapters.opcua.address_space import plan_folders
from softplc.core.datatypes import DataType
from softplc.core.tags import TagDef
from tests.opcua_support import client_for, running_plant


def _tags(count: int, group: str = "Cells", per_instance: int = 5) -> list[TagDef]:
    return [
        TagDef(f"c{i // per_instance:04d}_v{i % per_instance}", DataType.INT32, 0, group=f"{group}/c{i // per_instance:04d}")
        for i in range(count)
    ]


def _walk(folder, depth=0):
    yield folder, depth
    for child in folder.children:
        if hasattr(child, "children"):
            yield from _walk(child, depth + 1)


def test_big_groups_are_split_and_every_tag_appears_once() -> None:
    definitions = _tags(5000) + [TagDef(f"flat{i:04d}", DataType.BOOL, False) for i in range(1234)]
    definitions += [TagDef("_sys.state", DataType.STRING, "", group="_sys")]
    plant, diagnostics = plan_folders(definitions, folder_size=10)
    placed: list[str] = []
    for root in (plant, diagnostics):
        for folder, _ in _walk(root):
            assert len(folder.children) <= 10, folder.path
            placed.extend(child.name for child in folder.children if isinstance(child, TagDef))
    assert sorted(placed) == sorted(d.name for d in definitions)
    assert [c.name for c in diagnostics.children] == ["_sys.state"]
    # Chunk folders are named after the first and last thing in them, also when nested.
    # 1 + 1234 children of Plant: chunks of 10, of 100, of 1000.
    assert [child.name for child in plant.children] == ["Cells..flat0998", "flat0999..flat1233"]
    hundreds = plant.children[0].children
    assert hundreds[0].name == "Cells..flat0098" and hundreds[0].children[0].name == "Cells..flat0008"
    cells = hundreds[0].children[0].children[0]
    assert cells.name == "Cells" and cells.children[0].name == "c0000..c0099"
    assert cells.children[0].children[0].name == "c0000..c0009" and cells.children[0].children[0].children[0].name == "c0000"


def test_small_groups_keep_their_shape() -> None:
    plant, _ = plan_folders(_tags(15, group="Robots", per_instance=5), folder_size=100)
    assert [c.name for c in plant.children] == ["Robots"]
    robots = plant.children[0]
    assert [c.name for c in robots.children] == ["c0000", "c0001", "c0002"]
    assert [c.name for c in robots.children[0].children] == ["c0000_v0", "c0000_v1", "c0000_v2", "c0000_v3", "c0000_v4"]


async def test_a_served_big_folder_is_browsed_in_chunks(tmp_path) -> None:
    tags = "\n".join(f"  t{i:03d}: {{type: int16, group: Big}}" for i in range(35))
    text = f"version: 1\nplant: {{name: chunks}}\ntags:\n{tags}\n"
    async with running_plant(tmp_path, text, security=("None",), folder_size=10) as (_, server):
        async with client_for(server) as client:
            ns = await client.get_namespace_index("urn:softplc:tags")
            big = await client.nodes.objects.get_child([f"{ns}:Plant", f"{ns}:Big"])
            chunks = await big.get_children()
            names = [(await chunk.read_browse_name()).Name for chunk in chunks]
            assert names == ["t000..t009", "t010..t019", "t020..t029", "t030..t034"]
            last = await chunks[-1].get_children()
            assert [node.nodeid for node in last] == [ua.NodeId(f"t{i:03d}", ns) for i in range(30, 35)]
            assert await client.get_node(ua.NodeId("t034", ns)).read_value() == 0
