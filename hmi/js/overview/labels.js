// Where each robot's label (its name and task badge) goes on the floor: next to the robot, at
// the first spot, nearest first, that covers no station text, bar or footprint, no goal mark, no
// other robot and no other label, inside the map. A robot crowded in (parked at a station) gets
// its label a little further out, with a leader line to it.

const GAPS = [3, 16, 30, 46, 64];  // units between the robot's ring and its label, tried in order
// Directions, preferred first: above, below, right, left, then the diagonals and in between.
const DIRECTIONS = [-90, 90, 0, 180, -45, -135, 45, 135, -60, -120, 60, 120, -30, -150, 30, 150]
  .map((degrees) => [Math.cos(degrees * Math.PI / 180), Math.sin(degrees * Math.PI / 180)]);

/** The area two boxes ([left, top, right, bottom]) share. */
export function shared(a, b) {
  const width = Math.min(a[2], b[2]) - Math.max(a[0], b[0]);
  const height = Math.min(a[3], b[3]) - Math.max(a[1], b[1]);
  return width > 0 && height > 0 ? width * height : 0;
}

function outside(box, bounds) {
  const [left, top, right, bottom] = bounds;
  return Math.max(0, left - box[0]) + Math.max(0, box[2] - right) + Math.max(0, top - box[1]) + Math.max(0, box[3] - bottom);
}

/**
 * Place labels. `robots`: [{x, y, ring, width, height}] in map units (ring: the marker's radius);
 * `obstacles`: boxes to keep clear of; `bounds`: the map's box. Returns per robot
 * {box, gap}: the label's box and how far out it went (0: beside its robot).
 */
export function placeLabels(robots, obstacles, bounds) {
  const bodies = robots.map((robot) => [robot.x - robot.ring, robot.y - robot.ring, robot.x + robot.ring, robot.y + robot.ring]);
  const placed = [];
  return robots.map((robot, index) => {
    const reach = robot.ring + GAPS[GAPS.length - 1] + robot.width + robot.height;
    const near = (box) => box[2] > robot.x - reach && box[0] < robot.x + reach && box[3] > robot.y - reach && box[1] < robot.y + reach;
    const avoid = [...obstacles.filter(near), ...bodies.filter((body, other) => other !== index && near(body)), ...placed.filter(near)];
    let best = null;
    for (const gap of GAPS) {
      for (const [dx, dy] of DIRECTIONS) {
        const distance = robot.ring + gap;
        const cx = robot.x + dx * (distance + robot.width / 2 * Math.abs(dx) ** 0.5);
        const cy = robot.y + dy * (distance + robot.height / 2 * Math.abs(dy) ** 0.5);
        const box = [cx - robot.width / 2, cy - robot.height / 2, cx + robot.width / 2, cy + robot.height / 2];
        if (shared(box, bodies[index]) > 0) continue;  // never over its own robot
        let cost = outside(box, bounds) * 1000;
        for (const other of avoid) cost += shared(box, other);
        if (!best || cost < best.cost) best = { box, gap, cost };
        if (cost === 0) break;
      }
      if (best && best.cost === 0) break;
    }
    placed.push(best.box);
    return { box: best.box, gap: best.gap };
  });
}
