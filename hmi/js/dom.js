// DOM helpers. Text from the configuration (names, descriptions, units) only ever goes in as
// text (textContent / attribute values), never as markup: a "<script>" in a description shows
// as those characters. No module of the HMI uses innerHTML (tests/adapters/hmi/test_hmi_security.py checks).

const SVG_NS = 'http://www.w3.org/2000/svg';

function fill(node, attrs, children) {
  for (const [key, value] of Object.entries(attrs || {})) {
    if (value === undefined || value === null || value === false) continue;
    if (key === 'class') node.setAttribute('class', value);
    else if (key === 'text') node.textContent = String(value);
    else if (key.startsWith('on') && typeof value === 'function') node.addEventListener(key.slice(2), value);
    else if (key === 'dataset') Object.assign(node.dataset, value);
    else node.setAttribute(key, value === true ? '' : String(value));
  }
  for (const child of children.flat()) {
    if (child === undefined || child === null || child === false) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

/** An HTML element: el('td', {class: 'v', text: value}), el('div', {}, child, 'text'). */
export function el(tag, attrs, ...children) {
  return fill(document.createElement(tag), attrs, children);
}

/** An SVG element (createElementNS). */
export function svg(tag, attrs, ...children) {
  return fill(document.createElementNS(SVG_NS, tag), attrs, children);
}

export function clear(node) {
  while (node.firstChild) node.firstChild.remove();
  return node;
}

/** Set text only when it changed (keeps DOM mutations, and their cost, to real changes). */
export function setText(node, text) {
  const value = String(text);
  const only = node.firstChild;
  if (only && only.nodeType === Node.TEXT_NODE && !only.nextSibling) {
    if (only.data !== value) only.data = value;  // change the text node in place: no node made or dropped
  } else if (node.textContent !== value) {
    node.textContent = value;
  }
}

export function setClass(node, name, on) {
  node.classList.toggle(name, Boolean(on));
}
