// Independent VDA 5050 2.0 vehicles for the tests and benchmarks: vda-5050-lib's AgvController with its
// VirtualAgvAdapter (headless virtual vehicles nobody here wrote), one per entry of the configuration.
//
//   node tests/vda5050_node/vehicles.js '{"broker": "mqtt://127.0.0.1:1883", "vehicles": [{"manufacturer": "acme",
//     "serialNumber": "v1", "x": 7.925, "y": 5.925, "lastNodeId": "p1"}]}'
//
// Options: interface (uagv), speed (m/s, 1), stateInterval (ms, 30000: the library's default), heartbeat (s, 15),
// timeLapse (1), mapId (factory). Prints {"ready": N} on stdout once every vehicle is connected; SIGTERM stops
// them gracefully (connection OFFLINE), SIGKILL is a crash (the broker publishes their last will).
"use strict";
const { AgvController, VirtualAgvAdapter } = require("vda-5050-lib");

async function main() {
    const config = JSON.parse(process.argv[2] || "{}");
    const controllers = [];
    for (const vehicle of config.vehicles || []) {
        const agvId = { manufacturer: vehicle.manufacturer, serialNumber: vehicle.serialNumber };
        const clientOptions = {
            interfaceName: config.interface || "uagv",
            transport: { brokerUrl: config.broker, heartbeat: config.heartbeat || 15, reconnectPeriod: 500 },
            vdaVersion: "2.0.0",
        };
        const controllerOptions = {
            agvAdapterType: VirtualAgvAdapter,
            publishStateInterval: config.stateInterval || 30000,
            publishVisualizationInterval: 0,
        };
        const adapterOptions = {
            initialPosition: { mapId: config.mapId || "factory", x: vehicle.x, y: vehicle.y, theta: vehicle.theta || 0,
                               lastNodeId: vehicle.lastNodeId || "" },
            vehicleSpeed: config.speed || 1,
            timeLapse: config.timeLapse || 1,
        };
        const controller = new AgvController(agvId, clientOptions, controllerOptions, adapterOptions);
        await controller.start();
        if (config.factsheet !== false) {
            controller.updateFactsheet({
                headerId: 0, timestamp: new Date().toISOString(), version: "2.0.0", manufacturer: agvId.manufacturer,
                serialNumber: agvId.serialNumber,
                typeSpecification: { seriesName: "virtual", agvKinematic: "OMNI", agvClass: "CARRIER", maxLoadMass: vehicle.maxLoadMass || 20,
                                     localizationTypes: ["NATURAL"], navigationTypes: ["AUTONOMOUS"] },
                physicalParameters: { speedMin: 0.01, speedMax: config.speed || 1, accelerationMax: 1, decelerationMax: 1,
                                      heightMin: 0.4, heightMax: 0.4, width: 0.255, length: vehicle.length || 0.255 },
                protocolLimits: { maxStringLens: {}, maxArrayLens: {}, timing: { minOrderInterval: 0.1, minStateInterval: 0.1 } },
                protocolFeatures: { optionalParameters: [], agvActions: [] },
                // No localizationParameters: 2.0's table names it an object, the library's schema an integer.
                agvGeometry: {}, loadSpecification: {},
            });
        }
        controllers.push(controller);
    }
    process.stdout.write(JSON.stringify({ ready: controllers.length }) + "\n");
    const stop = async () => {
        await Promise.all(controllers.map(controller => controller.stop().catch(() => undefined)));
        process.exit(0);
    };
    process.on("SIGTERM", stop);
    process.on("SIGINT", stop);
}

main().catch(error => {
    process.stderr.write(`vehicles.js: ${error && error.stack || error}\n`);
    process.exit(1);
});
