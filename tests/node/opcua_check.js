// An independent OPC UA client (node-opcua) exercising softplc's server; run by tests/adapters/opcua/test_opcua_node.py.
//
//   node opcua_check.js ENDPOINT USER PASSWORD [SignAndEncrypt CERT.pem KEY.pem APPLICATION_URI [WAIT_FILE]]
//
// Connects (SecurityPolicy None, or Basic256Sha256 SignAndEncrypt with the given client
// certificate; user name + password), browses Objects/Plant, reads a few tags
// and their attributes, writes good and bad values, subscribes to a scan-driven tag, and prints
// one line "RESULT {json}" with everything it saw. Exit code 0 unless the script itself failed.
//
// With WAIT_FILE, a first connection is expected to be refused (certificate not yet trusted):
// the script prints "REFUSED <status>", waits until WAIT_FILE exists (the test trusts the
// certificate meanwhile), and then runs the checks. One process: node-opcua loads slowly.
"use strict";

const {
    OPCUAClient, MessageSecurityMode, SecurityPolicy, UserTokenType, AttributeIds, DataType,
    StatusCodes, ClientSubscription, ClientMonitoredItem, TimestampsToReturn,
} = require("node-opcua-client");

const fs = require("fs");

async function refusedFirst(options, endpoint, userName, password, waitFile) {
    const client = OPCUAClient.create(options);
    let status = "connected";
    try {
        await client.connect(endpoint);
        const session = await client.createSession({ type: UserTokenType.UserName, userName, password });
        await session.close();
    } catch (error) {
        status = (String(error.message).match(/Bad[A-Za-z]+/) || ["error"])[0];
    }
    await client.disconnect().catch(() => {});
    process.stdout.write(`REFUSED ${status}\n`);
    const deadline = Date.now() + 30000;
    while (!fs.existsSync(waitFile)) {
        if (Date.now() > deadline) throw new Error(`${waitFile} did not appear`);
        await new Promise((resolve) => setTimeout(resolve, 20));
    }
}

async function main() {
    const [endpoint, userName, password, mode, certificateFile, privateKeyFile, applicationUri, waitFile] = process.argv.slice(2);
    const secure = mode === "SignAndEncrypt";
    const options = {
        applicationName: "softplc-node-check",
        securityMode: secure ? MessageSecurityMode.SignAndEncrypt : MessageSecurityMode.None,
        securityPolicy: secure ? SecurityPolicy.Basic256Sha256 : SecurityPolicy.None,
        ...(secure ? { certificateFile, privateKeyFile, applicationUri } : {}),
        endpointMustExist: false,
        connectionStrategy: { maxRetry: 0, initialDelay: 100 },
        requestedSessionTimeout: 30000,
    };
    if (waitFile) {
        await refusedFirst(options, endpoint, userName, password, waitFile);
    }
    const client = OPCUAClient.create(options);
    const out = {};
    await client.connect(endpoint);
    const session = await client.createSession({ type: UserTokenType.UserName, userName, password });
    try {
        const namespaces = (await session.readNamespaceArray());
        const ns = namespaces.indexOf("urn:softplc:tags");
        out.namespaceIndex = ns;

        const objects = await session.browse("ns=0;i=85");
        out.objects = objects.references.map((r) => r.browseName.toString());
        const plant = objects.references.find((r) => r.browseName.name === "Plant");
        const plantChildren = await session.browse(plant.nodeId);
        out.plant = plantChildren.references.map((r) => r.browseName.name);

        const id = (tag) => `ns=${ns};s=${tag}`;
        const reads = await session.read([
            { nodeId: id("s1"), attributeId: AttributeIds.Value },
            { nodeId: id("i16"), attributeId: AttributeIds.DataType },
            { nodeId: id("ro_i32"), attributeId: AttributeIds.AccessLevel },
            { nodeId: id("i16"), attributeId: AttributeIds.AccessLevel },
            { nodeId: id("i16") + "/EURange", attributeId: AttributeIds.Value },
        ]);
        out.s1 = reads[0].value.value;
        out.i16DataType = reads[1].value.value.toString();
        out.roAccessLevel = reads[2].value.value;
        out.rwAccessLevel = reads[3].value.value;
        out.i16Range = { low: reads[4].value.value.low, high: reads[4].value.value.high };

        const writes = await session.write([
            { nodeId: id("i32"), attributeId: AttributeIds.Value, value: { value: { dataType: DataType.Int32, value: 4321 } } },
            { nodeId: id("ro_i32"), attributeId: AttributeIds.Value, value: { value: { dataType: DataType.Int32, value: 1 } } },
            { nodeId: id("i16"), attributeId: AttributeIds.Value, value: { value: { dataType: DataType.Int16, value: 500 } } },
            { nodeId: id("i32"), attributeId: AttributeIds.Value, value: { value: { dataType: DataType.String, value: "x" } } },
            { nodeId: id("f32"), attributeId: AttributeIds.Value, value: { value: { dataType: DataType.Float, value: 2.5 } } },
        ]);
        out.writes = writes.map((status) => status.name);

        // requestedPublishingInterval 0 would silently become 100 ms in node-opcua: ask for 1.
        const subscription = ClientSubscription.create(session, {
            requestedPublishingInterval: 1, requestedLifetimeCount: 1000, requestedMaxKeepAliveCount: 10,
            maxNotificationsPerPublish: 0, publishingEnabled: true, priority: 1,
        });
        const counts = [];
        const item = ClientMonitoredItem.create(subscription, { nodeId: id("count"), attributeId: AttributeIds.Value },
            { samplingInterval: 0, discardOldest: true, queueSize: 100 }, TimestampsToReturn.Both);
        await new Promise((resolve, reject) => {
            const timer = setTimeout(() => reject(new Error(`only ${counts.length} notifications in 5 s`)), 5000);
            item.on("changed", (dataValue) => {
                counts.push(Number(dataValue.value.value));
                if (counts.length >= 10) { clearTimeout(timer); resolve(); }
            });
        });
        out.counts = counts;
        await subscription.terminate();
    } finally {
        await session.close();
        await client.disconnect();
    }
    process.stdout.write("RESULT " + JSON.stringify(out) + "\n");
}

main().catch((error) => {
    process.stderr.write(`node-opcua check failed: ${error && error.stack ? error.stack : error}\n`);
    process.exit(1);
});
