// An independent client (node-opcua) reads softplc's history: raw values page by page with continuation
// points, processed Average (and Maximum), values at times; run by tests/adapters/opcua/test_opcua_history_node.py.
//
//   node history_check.js ENDPOINT USER PASSWORD EPOCH_MS
//
// Expects the plant of tests/opcua_history_support.py (simulated time from EPOCH_MS). Prints one line
// "RESULT {json}" with everything it saw; exit code 0 unless the script itself failed.
"use strict";

const {
    OPCUAClient, MessageSecurityMode, SecurityPolicy, UserTokenType, AttributeIds, TimestampsToReturn, BrowseDirection,
    HistoryReadRequest, ReadRawModifiedDetails, ReadProcessedDetails, ReadAtTimeDetails, AggregateFunction, resolveNodeId,
} = require("node-opcua-client");

function rows(result) {
    return (result.historyData ? result.historyData.dataValues : []).map((dv) => [
        dv.sourceTimestamp ? dv.sourceTimestamp.getTime() : null,
        dv.value.value === null || dv.value.value === undefined ? null : dv.value.value,
        dv.statusCode.value,
    ]);
}

async function main() {
    const [endpoint, userName, password, epochText] = process.argv.slice(2);
    const epoch = Number(epochText);
    const at = (seconds) => new Date(epoch + seconds * 1000);
    const client = OPCUAClient.create({
        applicationName: "softplc-node-history", securityMode: MessageSecurityMode.None, securityPolicy: SecurityPolicy.None,
        endpointMustExist: false, connectionStrategy: { maxRetry: 0, initialDelay: 100 }, requestedSessionTimeout: 30000,
    });
    const out = {};
    await client.connect(endpoint);
    const session = await client.createSession({ type: UserTokenType.UserName, userName, password });
    try {
        const ns = (await session.readNamespaceArray()).indexOf("urn:softplc:tags");
        const id = (tag) => `ns=${ns};s=${tag}`;
        const historyRead = async (details, nodeIds, points) => (await session.historyRead(new HistoryReadRequest({
            historyReadDetails: details, timestampsToReturn: TimestampsToReturn.Both, releaseContinuationPoints: false,
            nodesToRead: nodeIds.map((nodeId, i) => ({ nodeId, continuationPoint: points ? points[i] : null })),
        }))).results;

        const [historizing, accessLevel] = await session.read([
            { nodeId: id("level"), attributeId: AttributeIds.Historizing }, { nodeId: id("level"), attributeId: AttributeIds.AccessLevel }]);
        out.historizing = historizing.value.value;
        out.accessLevel = accessLevel.value.value;

        // Raw: level over [0, 25 s), 10 values a page, following the continuation points.
        const raw = new ReadRawModifiedDetails({ isReadModified: false, startTime: at(0), endTime: at(25), numValuesPerNode: 10, returnBounds: false });
        out.rawPages = [];
        let point = null;
        for (let page = 0; page < 10; page++) {
            const [result] = await historyRead(raw, [id("level")], [point]);
            out.rawPages.push({ status: result.statusCode.name, rows: rows(result) });
            point = result.continuationPoint;
            if (!point || point.length === 0) break;
        }
        const [bogus] = await historyRead(raw, [id("level")], [Buffer.from("not one of ours")]);
        out.bogusPoint = bogus.statusCode.name;

        // Processed: Average and Maximum of level per 10 s over [0, 30 s); Average of pressure over [0, 60 s).
        const processed = (start, end, intervalMs, aggregates) => new ReadProcessedDetails({
            startTime: at(start), endTime: at(end), processingInterval: intervalMs,
            aggregateType: aggregates.map((a) => resolveNodeId(`i=${a}`)),
            aggregateConfiguration: { useServerCapabilitiesDefaults: true },
        });
        const [average, maximum] = await historyRead(processed(0, 30, 10000, [AggregateFunction.Average, AggregateFunction.Maximum]), [id("level"), id("level")]);
        out.average = { status: average.statusCode.name, rows: rows(average) };
        out.maximum = { status: maximum.statusCode.name, rows: rows(maximum) };
        const [pressure] = await historyRead(processed(0, 60, 0, [AggregateFunction.Average]), [id("pressure")]);
        out.pressureAverage = rows(pressure);
        const [total] = await historyRead(processed(0, 30, 10000, [AggregateFunction.Total]), [id("level")]);
        out.total = total.statusCode.name;

        // At time: interpolated, then with simple bounds.
        const times = [at(2.5), at(7), at(25), at(-10)];
        const [levelAt] = await historyRead(new ReadAtTimeDetails({ reqTimes: times, useSimpleBounds: false }), [id("level")]);
        out.levelAt = rows(levelAt);
        const [pressureAt] = await historyRead(new ReadAtTimeDetails({ reqTimes: [at(25)], useSimpleBounds: false }), [id("pressure")]);
        const [pressureSimple] = await historyRead(new ReadAtTimeDetails({ reqTimes: [at(25)], useSimpleBounds: true }), [id("pressure")]);
        out.pressureAt = rows(pressureAt);
        out.pressureSimple = rows(pressureSimple);

        // Which aggregates the server says it has.
        const browsed = await session.browse({ nodeId: "i=11201", browseDirection: BrowseDirection.Forward, referenceTypeId: "i=35", includeSubtypes: true, resultMask: 63 });
        out.aggregateFunctions = browsed.references.map((r) => r.browseName.name).sort();
        const [maxValues] = await session.read([{ nodeId: "i=11273", attributeId: AttributeIds.Value }]);
        out.maxReturnDataValues = maxValues.value.value;
    } finally {
        await session.close();
        await client.disconnect();
    }
    console.log("RESULT " + JSON.stringify(out));
}

main().catch((error) => {
    console.error(error);
    process.exit(1);
});
