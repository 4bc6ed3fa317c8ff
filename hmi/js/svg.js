// A user's SVG drawing (e.g. from Inkscape) made safe to place in the page: parsed as XML (never
// as HTML markup), with scripts, event handlers, foreign content, animations and outside links
// removed, and `style="…"` attributes turned into presentation attributes (the page's
// Content-Security-Policy forbids inline styles, which Inkscape uses for everything).

const DROP = new Set(['script', 'foreignObject', 'iframe', 'object', 'embed', 'style', 'animate', 'set', 'animateMotion',
  'animateTransform', 'handler', 'listener', 'metadata']);
const PRESENTATION = new Set(['fill', 'fill-opacity', 'fill-rule', 'stroke', 'stroke-width', 'stroke-opacity', 'stroke-dasharray',
  'stroke-dashoffset', 'stroke-linecap', 'stroke-linejoin', 'stroke-miterlimit', 'opacity', 'display', 'visibility', 'font-size',
  'font-family', 'font-weight', 'font-style', 'text-anchor', 'dominant-baseline', 'letter-spacing', 'word-spacing', 'stop-color',
  'stop-opacity', 'color', 'clip-rule', 'paint-order', 'text-decoration', 'baseline-shift', 'alignment-baseline', 'mix-blend-mode']);
const SAFE_IMAGE = /^data:image\/(png|jpeg|gif|webp);base64,/i;

export function parseSvg(text) {
  // Rename style attributes before parsing: parsing them at all is an inline style the
  // Content-Security-Policy refuses (and reports); clean() turns them into attributes.
  // Event handler attributes likewise: the policy would refuse them anyway; they never get that far.
  const renamed = text.replace(/(\s)style\s*=\s*(["'])/g, '$1data-hmi-style=$2')
    .replace(/(\s)(on[a-zA-Z]+)\s*=\s*(["'])/g, '$1data-hmi-blocked-$2=$3');
  const doc = new DOMParser().parseFromString(renamed, 'image/svg+xml');
  const root = doc.documentElement;
  if (doc.getElementsByTagName('parsererror').length || root.localName !== 'svg') throw new Error('the view is not a valid SVG drawing');
  clean(root);
  if (!root.getAttribute('viewBox')) {
    const width = parseFloat(root.getAttribute('width')), height = parseFloat(root.getAttribute('height'));
    if (width > 0 && height > 0) root.setAttribute('viewBox', `0 0 ${width} ${height}`);
  }
  root.removeAttribute('width');
  root.removeAttribute('height');
  return document.importNode(root, true);
}

function clean(node) {
  for (const child of [...node.children]) {
    if (DROP.has(child.localName)) { child.remove(); continue; }
    clean(child);
  }
  for (const attribute of [...node.attributes]) {
    const name = attribute.name.toLowerCase();
    const local = attribute.localName.toLowerCase();
    if (name.startsWith('on') || name.startsWith('data-hmi-blocked-')) node.removeAttributeNode(attribute);
    else if (local === 'href') {
      const value = attribute.value.trim();
      if (!value.startsWith('#') && !(node.localName === 'image' && SAFE_IMAGE.test(value))) node.removeAttributeNode(attribute);
    } else if (name === 'style' || name === 'data-hmi-style') {
      for (const declaration of attribute.value.split(';')) {
        const at = declaration.indexOf(':');
        if (at < 0) continue;
        const property = declaration.slice(0, at).trim().toLowerCase();
        const value = declaration.slice(at + 1).trim();
        if (PRESENTATION.has(property) && value && !/url\s*\(\s*['"]?(?!#)/i.test(value)) node.setAttribute(property, value);
      }
      node.removeAttributeNode(attribute);
    }
  }
}
