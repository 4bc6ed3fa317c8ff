// node-opcua, a client none of us wrote, as an alarm display: run by tests/adapters/alarms/test_alarms_node.py.
//
//   node alarms_check.js ENDPOINT USER PASSWORD
//
// Subscribes to events on the Server object with node-opcua's own alarm filter (ofType
// AcknowledgeableConditionType), calls ConditionRefresh (node-opcua's callConditionRefresh) to
// learn what is active already, prints "REFRESHED", waits for a live transition of nav_failed
// (the test makes one), acknowledges level_hi with session.acknowledgeCondition, waits for the
// acknowledged event, and prints one line "RESULT {json}". Exit code 0 unless the script failed.
"use strict";

const {
    OPCUAClient, MessageSecurityMode, SecurityPolicy, UserTokenType, AttributeIds, TimestampsToReturn,
    constructEventFilter, ofType, resolveNodeId, callConditionRefresh,
} = require("node-opcua-client");

const FIELDS = ["EventId", "EventType", "SourceName", "Message", "Severity", "ConditionName", "Retain",
    "ActiveState", "ActiveState.Id", "AckedState.Id", "ConditionId"];

function plain(values) {
    const event = {};
    FIELDS.forEach((name, index) => {
        const value = values[index].value;
        if (value === null || value === undefined) {
            event[name] = null;
        } else if (Buffer.isBuffer(value)) {
            event[name] = value;
        } else if (value.text !== undefined) {
            event[name] = value.text;
        } else if (typeof value.toString === "function" && typeof value === "object") {
            event[name] = value.toString();
        } else {
            event[name] = value;
        }
    });
    return event;
}

function shown(event) {
    const copy = { ...event };
    if (Buffer.isBuffer(copy.EventId)) copy.EventId = copy.EventId.toString("hex");
    return copy;
}

async function until(check, what, timeout) {
    const deadline = Date.now() + timeout;
    while (!check()) {
        if (Date.now() > deadline) throw new Error(`timed out waiting for ${what}`);
        await new Promise((resolve) => setTimeout(resolve, 20));
    }
}

async function main() {
    const [endpoint, userName, password] = process.argv.slice(2);
    const client = OPCUAClient.create({
        applicationName: "softplc-node-alarms", securityMode: MessageSecurityMode.None, securityPolicy: SecurityPolicy.None,
        endpointMustExist: false, connectionStrategy: { maxRetry: 0, initialDelay: 100 }, requestedSessionTimeout: 30000,
    });
    await client.connect(endpoint);
    const session = await client.createSession({ type: UserTokenType.UserName, userName, password });
    const out = {};
    try {
        const subscription = await session.createSubscription2({
            requestedPublishingInterval: 20, requestedLifetimeCount: 600, requestedMaxKeepAliveCount: 20,
            maxNotificationsPerPublish: 1000, publishingEnabled: true, priority: 10,
        });
        const events = [];
        const filter = constructEventFilter(FIELDS, ofType("AcknowledgeableConditionType"));
        const item = await subscription.monitor(
            { nodeId: resolveNodeId("Server"), attributeId: AttributeIds.EventNotifier },
            { samplingInterval: 0, filter, queueSize: 1000, discardOldest: false }, TimestampsToReturn.Neither);
        item.on("changed", (values) => events.push(plain(values)));
        await new Promise((resolve) => setTimeout(resolve, 300));
        out.beforeRefresh = events.length;
        out.refreshStatus = String(await callConditionRefresh(session, subscription.subscriptionId));
        await until(() => events.some((e) => e.ConditionName === "level_hi"), "level_hi after ConditionRefresh", 5000);
        out.refreshed = events.map(shown);
        process.stdout.write("REFRESHED\n");
        await until(() => events.some((e) => e.ConditionName === "nav_failed"), "a live nav_failed event", 10000);
        out.live = shown(events.find((e) => e.ConditionName === "nav_failed"));
        const active = events.filter((e) => e.ConditionName === "level_hi").pop();
        const status = await session.acknowledgeCondition(resolveNodeId(active.ConditionId), active.EventId, "seen from node-opcua");
        out.acknowledgeStatus = status.name;
        await until(() => events.some((e) => e.ConditionName === "level_hi" && e["AckedState.Id"] === true), "the acknowledged event", 5000);
        out.acknowledged = shown(events.filter((e) => e.ConditionName === "level_hi").pop());
    } finally {
        await session.close();
        await client.disconnect();
    }
    process.stdout.write(`RESULT ${JSON.stringify(out)}\n`);
}

main().catch((error) => {
    process.stderr.write(`alarms_check.js failed: ${error.stack || error}\n`);
    process.exit(1);
});
