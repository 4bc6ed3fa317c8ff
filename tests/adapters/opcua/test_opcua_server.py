"""OPC UA server against a real asyncua client over loopback: address space, reads, writes, roles,
subscriptions, quality. One plant (real time, 10 ms task) is shared by the module."""

from __future__ import annotations

import pytest
import pytest_asyncio
from asyncua import ua
from asyncua.common.subscription import DataChangeNotif

from softplc.adapters.opcua.units import unit_id
from softplc.core.tags import Quality
from tests.opcua_support import PASSWORDS, client_for, running_plant, wait_until

pytestmark = pytest.mark.asyncio(loop_scope="module")


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def plant(tmp_path_factory: pytest.TempPathFactory):
    async with running_plant(tmp_path_factory.mktemp("opcua"), security=("None",)) as (runtime, server):
        yield runtime, server


@pytest_asyncio.fixture(loop_scope="module")
async def operator(plant):
    runtime, server = plant
    async with client_for(server, "operator") as client:
        yield client


async def _ns(client) -> int:
    return await client.get_namespace_index("urn:softplc:tags")


async def _names(node) -> list[str]:
    return [(await child.read_browse_name()).Name for child in await node.get_children()]


async def test_folders_follow_groups_and_diagnostics_have_their_own(plant, operator) -> None:
    ns = await _ns(operator)
    assert ns == plant[1].namespace_index
    objects = operator.nodes.objects
    assert {"Plant", "Diagnostics"} <= set(await _names(objects))
    plant_folder = await objects.get_child([f"{ns}:Plant"])
    names = await _names(plant_folder)
    assert names[0] == "Robots" and "s1" in names and "ro_i32" in names
    robots = await plant_folder.get_child([f"{ns}:Robots"])
    assert await _names(robots) == ["r01", "r02"]
    r01 = await robots.get_child([f"{ns}:r01"])
    children = await r01.get_children()
    assert [child.nodeid for child in children] == [ua.NodeId(name, ns) for name in ("r01_xpos", "r01_xgoal", "r01_status")]
    diagnostics = await objects.get_child([f"{ns}:Diagnostics"])
    diag_names = await _names(diagnostics)
    assert "_sys.state" in diag_names and "fast" in diag_names
    fast = await diagnostics.get_child([f"{ns}:fast"])
    assert "_sys.fast.cycles" in await _names(fast)


async def test_variables_carry_type_description_units_range_and_access(plant, operator) -> None:
    ns = await _ns(operator)
    expected_types = {"b1": ua.ObjectIds.Boolean, "i16": ua.ObjectIds.Int16, "u16": ua.ObjectIds.UInt16, "i32": ua.ObjectIds.Int32,
                      "u32": ua.ObjectIds.UInt32, "f32": ua.ObjectIds.Float, "f64": ua.ObjectIds.Double, "s1": ua.ObjectIds.String}
    for tag, type_id in expected_types.items():
        assert await operator.get_node(ua.NodeId(tag, ns)).read_data_type() == ua.NodeId(type_id), tag
    i16 = operator.get_node(ua.NodeId("i16", ns))
    assert (await i16.read_description()).Text == "a bounded int16"
    assert (await i16.read_attribute(ua.AttributeIds.AccessLevel)).Value.Value == 3
    assert (await operator.get_node(ua.NodeId("ro_i32", ns)).read_attribute(ua.AttributeIds.AccessLevel)).Value.Value == 1
    assert (await i16.read_attribute(ua.AttributeIds.ValueRank)).Value.Value == -1
    assert await i16.read_type_definition() == ua.NodeId(ua.ObjectIds.AnalogItemType)
    eu_range = await (await i16.get_child(["0:EURange"])).read_value()
    assert (eu_range.Low, eu_range.High) == (-100, 100)
    units = await (await i16.get_child(["0:EngineeringUnits"])).read_value()
    assert units.DisplayName.Text == "%" and units.UnitId == unit_id("%")
    xgoal = operator.get_node(ua.NodeId("r01_xgoal", ns))
    assert (await (await xgoal.get_child(["0:EURange"])).read_value()).High == 21.95
    assert (await (await xgoal.get_child(["0:EngineeringUnits"])).read_value()).UnitId == unit_id("m") == 0x4D5452
    assert await operator.get_node(ua.NodeId("u16", ns)).get_properties() == []


async def test_read_gives_value_quality_and_source_timestamp(plant, operator) -> None:
    runtime, _ = plant
    ns = await _ns(operator)
    value = await operator.get_node(ua.NodeId("s1", ns)).read_data_value()
    assert value.Value.Value == "hello" and value.StatusCode.is_good()
    assert abs(value.SourceTimestamp.timestamp() - runtime.db["s1"].timestamp) < 1e-3


async def test_multi_item_write_answers_each_item_and_applies_only_the_good_ones(plant, operator) -> None:
    runtime, _ = plant
    db = runtime.db
    ns = await _ns(operator)
    before = db.snapshot()
    items = [
        ("i16", ua.Variant(50, ua.VariantType.Int16), ua.StatusCodes.Good),
        ("u16", ua.Variant(7, ua.VariantType.Int64), ua.StatusCodes.Good),  # lossless integer conversion
        ("f64", ua.Variant(5, ua.VariantType.Int64), ua.StatusCodes.Good),  # Int64 → Double, exact
        ("f32", ua.Variant(0.5, ua.VariantType.Double), ua.StatusCodes.Good),  # exact in single precision
        ("s1", ua.Variant("world", ua.VariantType.String), ua.StatusCodes.Good),
        ("i32", ua.Variant(500, ua.VariantType.Int16), ua.StatusCodes.Good),
        ("i16", ua.Variant(101, ua.VariantType.Int16), ua.StatusCodes.BadOutOfRange),  # above max 100
        ("u32", ua.Variant(-1, ua.VariantType.Int32), ua.StatusCodes.BadOutOfRange),  # outside UInt32
        ("f32", ua.Variant(0.1, ua.VariantType.Double), ua.StatusCodes.BadTypeMismatch),  # inexact as Float
        ("u16", ua.Variant("7", ua.VariantType.String), ua.StatusCodes.BadTypeMismatch),
        ("b1", ua.Variant(1, ua.VariantType.Int32), ua.StatusCodes.BadTypeMismatch),
        ("i32", ua.Variant(2.5, ua.VariantType.Double), ua.StatusCodes.BadTypeMismatch),
        ("ro_i32", ua.Variant(1, ua.VariantType.Int32), ua.StatusCodes.BadNotWritable),
        ("no_such_tag", ua.Variant(1, ua.VariantType.Int32), ua.StatusCodes.BadNodeIdUnknown),
        ("/Plant/Robots", ua.Variant(1, ua.VariantType.Int32), ua.StatusCodes.BadNotWritable),
        ("i16/EURange", ua.Variant(1, ua.VariantType.Int32), ua.StatusCodes.BadNotWritable),
    ]
    nodes = [operator.get_node(ua.NodeId(tag, ns)) for tag, _, _ in items]
    results = await operator.write_values(nodes, [variant for _, variant, _ in items], raise_on_partial_error=False)
    assert [status.value for status in results] == [code for _, _, code in items]
    cycles = runtime.tasks[0].stats.cycles
    await wait_until(lambda: runtime.tasks[0].stats.cycles > cycles + 1)
    assert (db.value("i16"), db.value("u16"), db.value("f64"), db.value("f32"), db.value("s1"), db.value("i32")) == (50, 7, 5.0, 0.5, "world", 500)
    for untouched in ("u32", "b1", "ro_i32"):
        assert db.value(untouched) == before[untouched]
    # And the address space follows the database.
    await wait_until(lambda: _read(operator, ns, "s1", "world"))


async def _read(client, ns: int, tag: str, expected) -> bool:
    return await client.get_node(ua.NodeId(tag, ns)).read_value() == expected


async def test_write_of_quality_or_other_attributes_is_refused(plant, operator) -> None:
    ns = await _ns(operator)
    node = operator.get_node(ua.NodeId("i32", ns))
    bad = ua.DataValue(ua.Variant(1, ua.VariantType.Int32), StatusCode=ua.StatusCode(ua.StatusCodes.Bad))
    with pytest.raises(ua.UaStatusCodeError) as refused:
        await node.write_attribute(ua.AttributeIds.Value, bad)
    assert refused.value.code == ua.StatusCodes.BadWriteNotSupported
    with pytest.raises(ua.UaStatusCodeError) as refused:
        await node.write_attribute(ua.AttributeIds.DisplayName, ua.DataValue(ua.Variant(ua.LocalizedText("x"))))
    assert refused.value.code == ua.StatusCodes.BadNotWritable


async def test_roles_decide_who_writes(plant) -> None:
    runtime, server = plant
    db = runtime.db
    async with client_for(server) as anonymous, client_for(server, "viewer") as viewer, client_for(server, "engineer") as engineer:
        ns = await _ns(anonymous)
        assert await anonymous.get_node(ua.NodeId("s1", ns)).read_value() in ("hello", "world")  # anonymous may read
        for client in (anonymous, viewer):
            results = await client.write_values([client.get_node(ua.NodeId("i32", ns))], [ua.Variant(9, ua.VariantType.Int32)], raise_on_partial_error=False)
            assert results[0].value == ua.StatusCodes.BadUserAccessDenied
        results = await engineer.write_values(
            [engineer.get_node(ua.NodeId(t, ns)) for t in ("ro_i32", "i32")],
            [ua.Variant(42, ua.VariantType.Int32), ua.Variant(43, ua.VariantType.Int32)], raise_on_partial_error=False,
        )
        assert [r.value for r in results] == [ua.StatusCodes.Good, ua.StatusCodes.Good]
        await wait_until(lambda: db.value("ro_i32") == 42 and db.value("i32") == 43)
        # The engineer's force still obeys type and range.
        results = await engineer.write_values([engineer.get_node(ua.NodeId("i16", ns))], [ua.Variant(1000, ua.VariantType.Int16)], raise_on_partial_error=False)
        assert results[0].value == ua.StatusCodes.BadOutOfRange


async def test_user_access_level_tells_each_role_what_it_may_write(plant) -> None:
    _, server = plant
    expected = {None: (1, 1), "viewer": (1, 1), "operator": (3, 1), "engineer": (3, 3)}  # (rw tag i32, ro tag ro_i32)
    for user, (rw_level, ro_level) in expected.items():
        async with client_for(server, user) as client:
            ns = await _ns(client)
            levels = []
            for tag in ("i32", "ro_i32"):
                node = client.get_node(ua.NodeId(tag, ns))
                levels.append((await node.read_attribute(ua.AttributeIds.UserAccessLevel)).Value.Value)
                assert (await node.read_attribute(ua.AttributeIds.UserWriteMask)).Value.Value == 0
            assert tuple(levels) == (rw_level, ro_level), user
            # The AccessLevel stays the tag's own; nobody may write a property.
            assert (await client.get_node(ua.NodeId("ro_i32", ns)).read_attribute(ua.AttributeIds.AccessLevel)).Value.Value == 1
            eu_range = await client.get_node(ua.NodeId("i16", ns)).get_child(["0:EURange"])
            assert (await eu_range.read_attribute(ua.AttributeIds.UserAccessLevel)).Value.Value & 2 == 0, user


async def test_wrong_password_and_the_old_admin_backdoor_are_refused(plant) -> None:
    _, server = plant
    for user, password in (("operator", "not-the-password"), ("admin", "anything"), ("Admin", ""), ("nobody", PASSWORDS["operator"])):
        with pytest.raises(ua.UaStatusCodeError) as refused:
            async with client_for(server, user, password):
                pass
        assert refused.value.code == ua.StatusCodes.BadUserAccessDenied, user


async def test_nobody_may_add_or_delete_nodes(plant) -> None:
    _, server = plant
    async with client_for(server, "engineer") as engineer:
        ns = await _ns(engineer)
        with pytest.raises(ua.UaStatusCodeError) as refused:
            await engineer.nodes.objects.add_variable(ns, "intruder", 1.0)
        assert refused.value.code == ua.StatusCodes.BadUserAccessDenied
        with pytest.raises(ua.UaStatusCodeError):
            await engineer.delete_nodes([engineer.get_node(ua.NodeId("s1", ns))])
        assert await engineer.get_node(ua.NodeId("s1", ns)).read_browse_name()


class _Collector:
    def __init__(self) -> None:
        self.values: dict[str, list] = {}

    def datachange_notification(self, node, value, data: DataChangeNotif) -> None:
        self.values.setdefault(node.nodeid.Identifier, []).append(value)


async def test_subscription_receives_scan_driven_changes_and_a_program_sees_client_writes(plant, operator) -> None:
    ns = await _ns(operator)
    collector = _Collector()
    subscription = await operator.create_subscription(1, collector)
    await subscription.subscribe_data_change([operator.get_node(ua.NodeId(t, ns)) for t in ("count", "reply")], queuesize=100)
    await wait_until(lambda: len(collector.values.get("count", [])) >= 10)
    counts = collector.values["count"]
    assert counts == sorted(counts) and len(set(counts)) == len(counts)
    await operator.write_values([operator.get_node(ua.NodeId("request", ns))], [ua.Variant(1234, ua.VariantType.Int32)])
    await wait_until(lambda: 1234 in collector.values.get("reply", []))
    await subscription.delete()


async def test_quality_becomes_status_code(plant, operator) -> None:
    runtime, _ = plant
    ns = await _ns(operator)
    node = operator.get_node(ua.NodeId("f64", ns))
    for quality, check in ((Quality.BAD, "is_bad"), (Quality.UNCERTAIN, "is_uncertain"), (Quality.GOOD, "is_good")):
        runtime.db.submit_quality(["f64"], quality, "test")

        async def status_matches() -> bool:
            value = await node.read_data_value(raise_on_bad_status=False)
            return getattr(value.StatusCode, check)()

        await wait_until(status_matches)


async def test_system_tags_are_served(plant, operator) -> None:
    ns = await _ns(operator)
    cycles = operator.get_node(ua.NodeId("_sys.fast.cycles", ns))
    first = await cycles.read_value()

    async def advanced() -> bool:
        return await cycles.read_value() > first

    await wait_until(advanced)
    assert await operator.get_node(ua.NodeId("_sys.state", ns)).read_value() == "RUNNING"


async def test_a_client_write_and_the_program_in_the_same_cycle_follow_the_documented_rule(plant) -> None:
    runtime, server = plant
    db = runtime.db
    # `count` is incremented by the Ticker program every scan. The client's value is applied
    # at the start of a cycle, so that cycle's scan starts from it: 1_000_000 then 1_000_001.
    seen: list[int] = []
    stop = db.on_change(lambda tags: seen.extend(t.value for t in tags if t.name == "count"))
    try:
        async with client_for(server, "engineer") as engineer:
            ns = await _ns(engineer)
            results = await engineer.write_values([engineer.get_node(ua.NodeId("count", ns))], [ua.Variant(1_000_000, ua.VariantType.UInt32)])
            assert results[0].is_good()
        await wait_until(lambda: 1_000_001 in seen)
    finally:
        stop()
    at = seen.index(1_000_000)
    assert seen[at + 1] == 1_000_001  # nothing lost, nothing overwritten


async def test_operation_limits_are_advertised_and_enforced(plant, operator) -> None:
    limits = [ua.ObjectIds.Server_ServerCapabilities_OperationLimits_MaxNodesPerRead, ua.ObjectIds.Server_ServerCapabilities_OperationLimits_MaxNodesPerWrite]
    per_read, per_write = [await operator.get_node(ua.NodeId(limit)).read_value() for limit in limits]
    assert (per_read, per_write) == (20_000, 5_000)
    ns = await _ns(operator)
    node = operator.get_node(ua.NodeId("i32", ns))
    with pytest.raises(ua.UaStatusCodeError) as refused:
        await operator.write_values([node] * (per_write + 1), [ua.Variant(1, ua.VariantType.Int32)] * (per_write + 1))
    assert refused.value.code == ua.StatusCodes.BadTooManyOperations


async def test_browse_honours_max_references_with_continuation_points(plant, operator) -> None:
    ns = await _ns(operator)
    folder = ua.NodeId("/Plant", ns)

    def description() -> ua.BrowseDescription:
        return ua.BrowseDescription(NodeId=folder, BrowseDirection=ua.BrowseDirection.Forward,
                                    ReferenceTypeId=ua.NodeId(ua.ObjectIds.HierarchicalReferences), IncludeSubtypes=True,
                                    ResultMask=ua.BrowseResultMask.All)

    everything = (await operator.uaclient.browse(ua.BrowseParameters(NodesToBrowse=[description()])))[0]
    assert not everything.ContinuationPoint and len(everything.References) > 8
    first = (await operator.uaclient.browse(ua.BrowseParameters(NodesToBrowse=[description()], RequestedMaxReferencesPerNode=4)))[0]
    assert len(first.References) == 4 and first.ContinuationPoint
    pages, point = [first.References], first.ContinuationPoint
    while point:
        result = (await operator.uaclient.browse_next(ua.BrowseNextParameters(ReleaseContinuationPoints=False, ContinuationPoints=[point])))[0]
        assert result.StatusCode.is_good() and 0 < len(result.References) <= 4
        pages.append(result.References)
        point = result.ContinuationPoint
    assert [ref.NodeId for page in pages for ref in page] == [ref.NodeId for ref in everything.References]
    # A released point, or one never given out, is invalid afterwards.
    held = (await operator.uaclient.browse(ua.BrowseParameters(NodesToBrowse=[description()], RequestedMaxReferencesPerNode=2)))[0]
    released = await operator.uaclient.browse_next(ua.BrowseNextParameters(ReleaseContinuationPoints=True, ContinuationPoints=[held.ContinuationPoint]))
    assert released[0].StatusCode.is_good() and not released[0].References
    for point in (held.ContinuationPoint, b"made-up"):
        again = await operator.uaclient.browse_next(ua.BrowseNextParameters(ReleaseContinuationPoints=False, ContinuationPoints=[point]))
        assert again[0].StatusCode.value == ua.StatusCodes.BadContinuationPointInvalid
    # asyncua's own client follows continuation points by itself.
    children = await operator.get_node(folder).get_children()
    assert [child.nodeid for child in children] == [ref.NodeId for ref in everything.References]


async def test_browse_answers_like_asyncua_for_every_node_and_reference_filter(plant, operator) -> None:
    # The server remembers which reference types are subtypes of which (browsing.py); what a
    # client gets must stay what asyncua's own ViewService, walking the type tree, would answer.
    from asyncua.server.address_space import ViewService

    _, server = plant
    aspace = server.server.iserver.aspace
    walking = ViewService(aspace)
    filters = [(ua.ObjectIds.HierarchicalReferences, True), (ua.ObjectIds.HierarchicalReferences, False),
               (ua.ObjectIds.Organizes, True), (ua.ObjectIds.HasChild, True), (ua.ObjectIds.HasComponent, False),
               (ua.ObjectIds.NonHierarchicalReferences, True), (ua.ObjectIds.Null, False)]
    nodes = [node_id for node_id in aspace.keys() if node_id.NamespaceIndex == await _ns(operator)][:200]
    nodes += [ua.NodeId(ua.ObjectIds.ObjectsFolder), ua.NodeId(ua.ObjectIds.Server), ua.NodeId(ua.ObjectIds.RootFolder)]
    for reference_type, subtypes in filters:
        descriptions = [ua.BrowseDescription(NodeId=node_id, BrowseDirection=ua.BrowseDirection.Both,
                                             ReferenceTypeId=ua.NodeId(reference_type), IncludeSubtypes=subtypes,
                                             ResultMask=ua.BrowseResultMask.All) for node_id in nodes]
        served = await operator.uaclient.browse(ua.BrowseParameters(NodesToBrowse=descriptions))
        expected = walking.browse(ua.BrowseParameters(NodesToBrowse=descriptions))
        assert [[(r.NodeId, r.ReferenceTypeId, r.IsForward) for r in result.References] for result in served] == \
               [[(r.NodeId, r.ReferenceTypeId, r.IsForward) for r in result.References] for result in expected]
        if subtypes:  # found only through the type tree: what the cache answers
            assert sum(len(result.References) for result in served) > 0
