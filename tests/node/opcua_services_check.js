// An independent client (node-opcua) checks what softplc's server tells about time, deadbands,
// queue sizes, history and methods; run by tests/adapters/opcua/test_opcua_node.py.
//
//   node opcua_services_check.js ENDPOINT USER PASSWORD
//
// Expects the plant of tests/opcua_support.py (count +1 per 10 ms scan, ramp = count % 1000 with
// EURange 0..1000). Prints one line "RESULT {json}" with everything it saw; exit code 0 unless the
// script itself failed.
"use strict";

const {
    OPCUAClient, MessageSecurityMode, SecurityPolicy, UserTokenType, AttributeIds, ClientSubscription,
    ClientMonitoredItem, TimestampsToReturn, DataChangeFilter, DeadbandType, DataChangeTrigger, MonitoringMode,
} = require("node-opcua-client");

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// Values of a monitored item until `count` arrived (or `ms` passed).
function collect(subscription, nodeId, parameters, count, ms) {
    const item = ClientMonitoredItem.create(subscription, { nodeId, attributeId: AttributeIds.Value }, parameters, TimestampsToReturn.Both);
    const values = [];
    return new Promise((resolve) => {
        const done = () => { item.terminate().catch(() => {}); resolve(values); };
        const timer = setTimeout(done, ms);
        item.on("changed", (dataValue) => {
            const value = dataValue.value.value;
            values.push(value instanceof Date ? value.toISOString() : Number(value));
            if (values.length >= count) { clearTimeout(timer); done(); }
        });
        item.on("err", (message) => { values.push(`err ${message}`); clearTimeout(timer); done(); });
    });
}

function deadband(type, value) {
    return new DataChangeFilter({ trigger: DataChangeTrigger.StatusValue, deadbandType: type, deadbandValue: value });
}

async function main() {
    const [endpoint, userName, password] = process.argv.slice(2);
    const client = OPCUAClient.create({
        applicationName: "softplc-node-services", securityMode: MessageSecurityMode.None, securityPolicy: SecurityPolicy.None,
        endpointMustExist: false, connectionStrategy: { maxRetry: 0, initialDelay: 100 }, requestedSessionTimeout: 30000,
    });
    const out = {};
    await client.connect(endpoint);
    const session = await client.createSession({ type: UserTokenType.UserName, userName, password });
    try {
        const ns = (await session.readNamespaceArray()).indexOf("urn:softplc:tags");
        const id = (tag) => `ns=${ns};s=${tag}`;

        // Server/ServerStatus/CurrentTime, twice, and the ServerStatus structure.
        const times = [];
        for (let i = 0; i < 2; i++) {
            const [current, status] = await session.read([
                { nodeId: "i=2258", attributeId: AttributeIds.Value }, { nodeId: "i=2256", attributeId: AttributeIds.Value }]);
            times.push({
                dataType: current.value.dataType, currentTime: current.value.value ? current.value.value.toISOString() : null,
                statusCurrentTime: status.value.value.currentTime.toISOString(), statusStartTime: status.value.value.startTime.toISOString(),
                clientTime: new Date().toISOString(),
            });
            if (i === 0) await sleep(1100);
        }
        out.times = times;

        const subscription = ClientSubscription.create(session, {
            requestedPublishingInterval: 20, requestedLifetimeCount: 1000, requestedMaxKeepAliveCount: 10,
            maxNotificationsPerPublish: 0, publishingEnabled: true, priority: 1,
        });
        const plain = { samplingInterval: 0, discardOldest: true, queueSize: 10 };
        // A watchdog's view of CurrentTime, and two deadbands on tags that drift by 1 per scan.
        [out.currentTimeChanges, out.absolute, out.percent] = await Promise.all([
            collect(subscription, "i=2258", plain, 3, 8000),
            collect(subscription, id("count"), { ...plain, filter: deadband(DeadbandType.Absolute, 10) }, 8, 8000),
            collect(subscription, id("ramp"), { ...plain, filter: deadband(DeadbandType.Percent, 1) }, 8, 8000),
        ]);

        // Filters that do not fit their node, beside a good item, in one request; queue sizes.
        const request = (tag, filter, queueSize) => ({
            itemToMonitor: { nodeId: id(tag), attributeId: AttributeIds.Value }, monitoringMode: MonitoringMode.Reporting,
            requestedParameters: { clientHandle: 900 + queueSize, samplingInterval: 0, filter, queueSize, discardOldest: true },
        });
        const created = await session.createMonitoredItems({
            subscriptionId: subscription.subscriptionId, timestampsToReturn: TimestampsToReturn.Both,
            itemsToCreate: [
                request("s1", deadband(DeadbandType.Absolute, 1), 1),
                request("b1", deadband(DeadbandType.Absolute, 1), 2),
                request("f64", deadband(DeadbandType.Percent, 5), 3),
                request("i16", deadband(DeadbandType.Percent, 150), 4),
                request("count", null, 0),
                request("count", null, 5000),
            ],
        });
        out.created = created.results.map((result) => [result.statusCode.name, result.revisedQueueSize]);
        const good = created.results.filter((result) => result.statusCode.isGood()).map((result) => result.monitoredItemId);
        await session.deleteMonitoredItems({ subscriptionId: subscription.subscriptionId, monitoredItemIds: good });
        await subscription.terminate();

        // History: an unknown node, a tag without history.
        const history = await session.readHistoryValue([id("no_such_tag"), id("count")], new Date(Date.now() - 60000), new Date());
        out.history = history.map((result) => result.statusCode.name);

        // Call: an unknown method of the Server object, a known method of an unknown object.
        const calls = await session.call([
            { objectId: "i=2253", methodId: `ns=${ns};s=no_such_method`, inputArguments: [] },
            { objectId: `ns=${ns};s=no_such_object`, methodId: "i=11492", inputArguments: [] },
        ]);
        out.calls = calls.map((result) => result.statusCode.name);
    } finally {
        await session.close();
        await client.disconnect();
    }
    process.stdout.write("RESULT " + JSON.stringify(out) + "\n");
}

main().catch((error) => {
    process.stderr.write(`node-opcua services check failed: ${error && error.stack ? error.stack : error}\n`);
    process.exit(1);
});
