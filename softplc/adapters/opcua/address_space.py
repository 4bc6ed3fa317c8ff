"""The OPC UA address space of a plant: folders by group, one Variable per tag, properties.

Layout (all NodeIds are strings in our namespace):

    Objects/Plant/<group path>/<tag>          e.g. Plant/Robots/r01/r01_xpos   ns=N;s=r01_xpos
    Objects/Diagnostics/<task>/<_sys tag>     the `_sys.` tags                 ns=N;s=_sys.plant.cycles
    <tag>/EngineeringUnits, <tag>/EURange     properties (when the YAML gives unit / min / max)
    folders                                   ns=N;s=/Plant/Robots/r01

No folder gets more than `folder_size` children: a bigger one is split into sub-folders named
after their first and last child ("r001_x..r034_y"), recursively.

Nodes are built directly as asyncua `NodeData` (asyncua 2.1.0 is pinned): the generic AddNodes
path costs ~170 µs a node and scans the parent's references on every insert, which would make
10k tags take seconds. Building the same structures directly takes a fraction of that.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

from asyncua import ua
from asyncua.server.address_space import AddressSpace, AttributeValue, NodeData

from softplc.adapters.opcua.units import eu_information
from softplc.core.tags import Access, Tag, TagDef
from softplc.protocols.opcua_variants import DATA_TYPE_IDS, data_value

PLANT_FOLDER = "Plant"
DIAGNOSTICS_FOLDER = "Diagnostics"
SYSTEM_GROUP = "_sys"

_ORGANIZES = ua.NodeId(ua.ObjectIds.Organizes)
_HAS_PROPERTY = ua.NodeId(ua.ObjectIds.HasProperty)
_HAS_TYPE_DEFINITION = ua.NodeId(ua.ObjectIds.HasTypeDefinition)
_FOLDER_TYPE = ua.NodeId(ua.ObjectIds.FolderType)
_PROPERTY_TYPE = ua.NodeId(ua.ObjectIds.PropertyType)
_BASE_VARIABLE_TYPE = ua.NodeId(ua.ObjectIds.BaseDataVariableType)
_ANALOG_ITEM_TYPE = ua.NodeId(ua.ObjectIds.AnalogItemType)
_BASE_ANALOG_TYPE = ua.NodeId(ua.ObjectIds.BaseAnalogType)
_OBJECTS_FOLDER = ua.NodeId(ua.ObjectIds.ObjectsFolder)
_RANGE = ua.NodeId(ua.ObjectIds.Range)
_EU_INFORMATION = ua.NodeId(ua.ObjectIds.EUInformation)

_BUILD_SLICE = 0.005
READ = 1  # AccessLevel bit CurrentRead
READ_WRITE = 3  # CurrentRead | CurrentWrite
HISTORY_READ = 4  # AccessLevel bit HistoryRead: the tag has history (a HistoryProvider says so)


def _never(tag: str) -> bool:
    return False


def tag_node_id(name: str, namespace_index: int) -> ua.NodeId:
    """The NodeId of a tag's Variable: `ns=<namespace_index>;s=<tag name>`."""
    return ua.NodeId(name, namespace_index)


@dataclass
class _Folder:
    path: str  # "/Plant/Robots/r01"
    name: str
    children: list[_Folder | TagDef] = field(default_factory=list)
    span: tuple[str, str] | None = None  # a chunk folder: names of its first and last leaf
    index: dict[str, _Folder] = field(default_factory=dict)

    def folder(self, name: str) -> _Folder:
        child = self.index.get(name)
        if child is None:
            child = _Folder(f"{self.path}/{name}", name)
            self.index[name] = child
            self.children.append(child)
        return child


def _first(child: _Folder | TagDef) -> str:
    return child.span[0] if isinstance(child, _Folder) and child.span else child.name


def _last(child: _Folder | TagDef) -> str:
    return child.span[1] if isinstance(child, _Folder) and child.span else child.name


def plan_folders(definitions: Iterable[TagDef], folder_size: int) -> list[_Folder]:
    """The folder tree (Plant and Diagnostics) of the tags, split so no folder is too big."""
    plant = _Folder("/" + PLANT_FOLDER, PLANT_FOLDER)
    diagnostics = _Folder("/" + DIAGNOSTICS_FOLDER, DIAGNOSTICS_FOLDER)
    for definition in definitions:
        parts = [part for part in definition.group.split("/") if part]
        if parts and parts[0] == SYSTEM_GROUP:
            folder, parts = diagnostics, parts[1:]
        else:
            folder = plant
        for part in parts:
            folder = folder.folder(part)
        folder.children.append(definition)
    for root in (plant, diagnostics):
        _split(root, folder_size)
    return [plant, diagnostics]


def _split(folder: _Folder, size: int) -> None:
    for child in folder.children:
        if isinstance(child, _Folder):
            _split(child, size)
    while len(folder.children) > size:
        chunks = [folder.children[i:i + size] for i in range(0, len(folder.children), size)]
        grouped: list[_Folder | TagDef] = []
        for chunk in chunks:
            span = (_first(chunk[0]), _last(chunk[-1]))
            name = f"{span[0]}..{span[1]}"
            part = _Folder(f"{folder.path}/{name}", name, list(chunk), span=span)
            grouped.append(part)
        folder.children = grouped


class AddressSpaceBuilder:
    """Creates our folders, tag Variables and their properties in an asyncua address space."""

    def __init__(self, aspace: AddressSpace, namespace_index: int) -> None:
        self.aspace = aspace
        self.ns = namespace_index
        self.values: dict[str, AttributeValue] = {}  # tag name → its Value attribute
        self.node_count = 0
        self._built = datetime.now(timezone.utc)
        # Attributes that are alike on many nodes and never written (our Write service refuses
        # every attribute but Value) are one shared object: a third fewer objects to build.
        self._static: dict[Any, AttributeValue] = {}
        self._data_types: dict[ua.NodeId, AttributeValue] = {}
        self._descriptions: dict[str, AttributeValue] = {}
        self._historized: Callable[[str], bool] = _never

    def _shared(self, value: Any, variant_type: ua.VariantType) -> AttributeValue:
        key = (value, variant_type)
        attribute = self._static.get(key)
        if attribute is None:
            attribute = self._static[key] = AttributeValue(ua.DataValue(ua.Variant(value, variant_type)))
        return attribute

    async def build(self, roots: Sequence[_Folder], tags: dict[str, Tag], historized: Callable[[str], bool] | None = None) -> None:
        """Add every folder and tag under Objects (a root folder with no children is left out).

        `historized(tag)`: whether a tag has history (AccessLevel HistoryRead, Historizing).
        Yields to the event loop every few milliseconds so a big plant does not stall others.
        """
        self._historized = historized or _never
        objects = self.aspace[_OBJECTS_FOLDER]
        self._yield_at = time.perf_counter() + _BUILD_SLICE
        for root in roots:
            if root.children:
                self._add_folder(root, objects)
                await self._add_tree(root, tags)

    async def _add_tree(self, folder: _Folder, tags: dict[str, Tag]) -> None:
        parent = self.aspace[ua.NodeId(folder.path, self.ns)]
        for child in folder.children:
            if isinstance(child, _Folder):
                self._add_folder(child, parent)
                await self._add_tree(child, tags)
            else:
                self._add_variable(child, parent, tags[child.name])
        if time.perf_counter() > self._yield_at:
            await asyncio.sleep(0)
            self._yield_at = time.perf_counter() + _BUILD_SLICE

    # -- nodes ----------------------------------------------------------------------------

    def _description(self, text: str) -> AttributeValue:
        attribute = self._descriptions.get(text)
        if attribute is None:
            attribute = AttributeValue(ua.DataValue(ua.Variant(ua.LocalizedText(text), ua.VariantType.LocalizedText)))
            if len(self._descriptions) < 10_000:
                self._descriptions[text] = attribute
        return attribute

    def _base_node(
        self, node_id: ua.NodeId, name: str, description: str, node_class: ua.NodeClass, browse_ns: int | None = None
    ) -> NodeData:
        node = NodeData(node_id)
        qualified = ua.QualifiedName(name, self.ns if browse_ns is None else browse_ns)
        zero_mask = self._shared(0, ua.VariantType.UInt32)
        node.attributes = {
            ua.AttributeIds.NodeId: AttributeValue(ua.DataValue(ua.Variant(node_id, ua.VariantType.NodeId))),
            ua.AttributeIds.BrowseName: AttributeValue(ua.DataValue(ua.Variant(qualified, ua.VariantType.QualifiedName))),
            ua.AttributeIds.NodeClass: self._shared(node_class, ua.VariantType.Int32),
            ua.AttributeIds.DisplayName: AttributeValue(ua.DataValue(ua.Variant(ua.LocalizedText(name), ua.VariantType.LocalizedText))),
            ua.AttributeIds.Description: self._description(description),
            ua.AttributeIds.WriteMask: zero_mask,
            ua.AttributeIds.UserWriteMask: zero_mask,
        }
        self.aspace[node_id] = node
        self.node_count += 1
        return node

    def _variable_attributes(self, node: NodeData, value: AttributeValue, data_type: ua.NodeId, access: int,
                             historizing: bool = False) -> None:
        data_type_attribute = self._data_types.get(data_type)
        if data_type_attribute is None:
            data_type_attribute = self._data_types[data_type] = AttributeValue(ua.DataValue(ua.Variant(data_type, ua.VariantType.NodeId)))
        access_attribute = self._shared(access, ua.VariantType.Byte)
        node.attributes.update({
            ua.AttributeIds.Value: value,
            ua.AttributeIds.DataType: data_type_attribute,
            ua.AttributeIds.ValueRank: self._shared(-1, ua.VariantType.Int32),
            ua.AttributeIds.AccessLevel: access_attribute,
            ua.AttributeIds.UserAccessLevel: access_attribute,
            ua.AttributeIds.MinimumSamplingInterval: self._shared(0.0, ua.VariantType.Double),
            ua.AttributeIds.Historizing: self._shared(historizing, ua.VariantType.Boolean),
        })

    def _link(self, parent: NodeData, child: NodeData, reference: ua.NodeId, node_class: ua.NodeClass, type_definition: ua.NodeId) -> None:
        """Forward reference parent → child, inverse child → parent, and the child's type."""
        browse_name = child.attributes[ua.AttributeIds.BrowseName].value.Value.Value  # type: ignore[union-attr]
        display_name = child.attributes[ua.AttributeIds.DisplayName].value.Value.Value  # type: ignore[union-attr]
        parent.references.append(ua.ReferenceDescription(
            ReferenceTypeId=reference, IsForward=True, NodeId=child.nodeid, BrowseName=browse_name,
            DisplayName=display_name, NodeClass=node_class, TypeDefinition=type_definition,
        ))
        parent_attributes = parent.attributes
        child.references.append(ua.ReferenceDescription(
            ReferenceTypeId=reference, IsForward=False, NodeId=parent.nodeid,
            BrowseName=parent_attributes[ua.AttributeIds.BrowseName].value.Value.Value,  # type: ignore[union-attr]
            DisplayName=parent_attributes[ua.AttributeIds.DisplayName].value.Value.Value,  # type: ignore[union-attr]
            NodeClass=parent_attributes[ua.AttributeIds.NodeClass].value.Value.Value,  # type: ignore[union-attr]
        ))
        child.references.append(ua.ReferenceDescription(
            ReferenceTypeId=_HAS_TYPE_DEFINITION, IsForward=True, NodeId=type_definition,
            NodeClass=ua.NodeClass.VariableType if node_class == ua.NodeClass.Variable else ua.NodeClass.ObjectType,
        ))

    def _add_folder(self, folder: _Folder, parent: NodeData) -> None:
        node = self._base_node(ua.NodeId(folder.path, self.ns), folder.name, "", ua.NodeClass.Object)
        node.attributes[ua.AttributeIds.EventNotifier] = self._shared(0, ua.VariantType.Byte)
        self._link(parent, node, _ORGANIZES, ua.NodeClass.Object, _FOLDER_TYPE)

    def _add_variable(self, definition: TagDef, parent: NodeData, tag: Tag) -> None:
        node = self._base_node(ua.NodeId(definition.name, self.ns), definition.name, definition.description, ua.NodeClass.Variable)
        value = AttributeValue(data_value(definition, tag.value, tag.quality, tag.timestamp, tag.forced))
        access = READ_WRITE if definition.access is Access.RW else READ
        historizing = self._historized(definition.name)
        if historizing:
            access |= HISTORY_READ
        self._variable_attributes(node, value, DATA_TYPE_IDS[definition.type], access, historizing)
        numeric = definition.type.is_numeric
        has_range = numeric and (definition.min is not None or definition.max is not None)
        has_unit = bool(definition.unit)
        type_definition = _ANALOG_ITEM_TYPE if has_range else _BASE_ANALOG_TYPE if has_unit and numeric else _BASE_VARIABLE_TYPE
        self._link(parent, node, _ORGANIZES, ua.NodeClass.Variable, type_definition)
        self.values[definition.name] = value
        extension = ua.VariantType.ExtensionObject
        if has_range:
            self._add_property(node, definition.name, "EURange", ua.Variant(eu_range(definition), extension), _RANGE)
        if has_unit:
            units = ua.Variant(eu_information(definition.unit), extension)
            self._add_property(node, definition.name, "EngineeringUnits", units, _EU_INFORMATION)

    def _add_property(self, owner: NodeData, tag_name: str, name: str, value: ua.Variant, data_type: ua.NodeId) -> None:
        node = self._base_node(ua.NodeId(f"{tag_name}/{name}", self.ns), name, "", ua.NodeClass.Variable, browse_ns=0)
        constant = AttributeValue(ua.DataValue(value, SourceTimestamp=self._built, ServerTimestamp=self._built))
        self._variable_attributes(node, constant, data_type, READ)
        self._link(owner, node, _HAS_PROPERTY, ua.NodeClass.Variable, _PROPERTY_TYPE)


def eu_range(definition: TagDef) -> ua.Range:
    """EURange of a numeric tag: its min/max, the type's own limit where one is not given."""
    low, high = definition.type.limits or (-math.inf, math.inf)
    low = definition.min if definition.min is not None else low
    high = definition.max if definition.max is not None else high
    # An infinite bound is legal but confuses some clients; use the largest finite double.
    return ua.Range(Low=max(float(low), -1.7976931348623157e308), High=min(float(high), 1.7976931348623157e308))
