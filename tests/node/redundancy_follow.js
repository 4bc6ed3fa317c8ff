// A node-opcua client that follows the active of a redundant pair (tests/adapters/redundancy/test_pair_faults.py).
//
//   node redundancy_follow.js SECONDS ENDPOINT_A ENDPOINT_B
//
// It keeps a session on each server of the set and reads, every 200 ms, what OPC UA Part 4 §6.6.2
// says a client of a non-transparent redundant set reads: ServiceLevel (i=2267), and once
// RedundancySupport (i=3709) and ServerUriArray (i=11314). It uses the server with the highest
// ServiceLevel of at least 200 and reads the tag `scans` from it. Each time the server it uses
// changes it prints "ACTIVE {json}"; at the end "RESULT {json}". A session that breaks is
// re-created on the next round (the dead server counts as ServiceLevel 0).
"use strict";

const { OPCUAClient, MessageSecurityMode, SecurityPolicy, AttributeIds } = require("node-opcua-client");

// Every call has a deadline: a request to a server killed under it, or a connection that a loaded
// machine makes slowly, must not keep the loop (or, at the end, the process) from going on.
function within(ms, promise) {
    return Promise.race([promise, new Promise((_, no) => setTimeout(() => no(new Error("timeout")), ms).unref())]);
}

async function session(endpoint) {
    const client = OPCUAClient.create({
        applicationName: "softplc-redundancy-follow",
        securityMode: MessageSecurityMode.None,
        securityPolicy: SecurityPolicy.None,
        endpointMustExist: false,
        connectionStrategy: { maxRetry: 0, initialDelay: 100 },
        requestedSessionTimeout: 10000,
        keepSessionAlive: false,
    });
    await client.connect(endpoint);
    return { client, session: await client.createSession() };
}

async function main() {
    const [seconds, ...endpoints] = process.argv.slice(2);
    const sessions = {};
    const seen = { redundancy: {}, switches: [] };
    let using = null;
    const deadline = Date.now() + Number(seconds) * 1000;
    while (Date.now() < deadline) {
        const levels = {};
        for (const endpoint of endpoints) {
            try {
                if (!sessions[endpoint]) {
                    const opening = session(endpoint);
                    try {
                        sessions[endpoint] = await within(1500, opening);
                    } catch (error) {  // too slow: a session opened after all is closed, not left to hold the process
                        opening.then((late) => late.client.disconnect().catch(() => {}), () => {});
                        throw error;
                    }
                }
                const { session: s } = sessions[endpoint];
                if (!seen.redundancy[endpoint]) {
                    const [support, uris] = await within(1000, s.read([
                        { nodeId: "ns=0;i=3709", attributeId: AttributeIds.Value },
                        { nodeId: "ns=0;i=11314", attributeId: AttributeIds.Value },
                    ]));
                    seen.redundancy[endpoint] = { support: support.value.value, uris: uris.value.value };
                }
                const level = await within(1000, s.read({ nodeId: "ns=0;i=2267", attributeId: AttributeIds.Value }));
                levels[endpoint] = level.value.value;
            } catch (error) {
                levels[endpoint] = 0;
                const broken = sessions[endpoint];
                delete sessions[endpoint];
                if (broken) broken.client.disconnect().catch(() => {});
            }
        }
        const best = Object.entries(levels).filter(([, level]) => level >= 200).sort((x, y) => y[1] - x[1])[0];
        const chosen = best ? best[0] : null;
        if (chosen !== using) {
            using = chosen;
            let scans = null;
            if (chosen) {
                try {
                    const ns = (await within(1000, sessions[chosen].session.readNamespaceArray())).indexOf("urn:softplc:tags");
                    scans = (await within(1000, sessions[chosen].session.read({ nodeId: `ns=${ns};s=scans`, attributeId: AttributeIds.Value }))).value.value;
                } catch (error) { scans = null; }
            }
            const line = { at: Date.now(), using: chosen, levels, scans };
            seen.switches.push(line);
            process.stdout.write(`ACTIVE ${JSON.stringify(line)}\n`);
        }
        await new Promise((resolve) => setTimeout(resolve, 200));
    }
    process.stdout.write(`RESULT ${JSON.stringify(seen)}\n`);
    for (const { client, session: s } of Object.values(sessions)) {
        await within(2000, s.close()).catch(() => {});
        await within(2000, client.disconnect()).catch(() => {});
    }
}

// The result is printed; whatever a dead server's connection still holds open does not keep the process.
main().then(() => process.exit(0), (error) => { process.stderr.write(`${error.stack || error}\n`); process.exit(1); });
