// The text over the picture: the touched residue, contact, clutch and the force (top left),
// the status line (bottom), the numbered marks where they are, and a one-line message when
// the page cannot draw at all.

function element(parent, tag, className) {
  const e = document.createElement(tag);
  if (className) e.className = className;
  parent.appendChild(e);
  return e;
}

const STATUS_EVERY_MS = 250; // the status line's figures change this often at most

// Sets an element's text only when it changes: each change costs the browser a repaint.
function setText(e, text) {
  if (e.textContent !== text) e.textContent = text;
}

export class Overlay {
  constructor(root) {
    this.root = root;
    this.info = element(root, "div", "info");
    this.touched = element(this.info, "div", "touched");
    this.states = element(this.info, "div", "states");
    this.status = element(root, "div", "status");
    this.marks = element(root, "div", "marks");
    this.badges = new Map();
    this.statusAt = -Infinity;
  }

  fatal(text) {
    this.status.textContent = text;
    this.status.classList.add("fatal");
  }

  update(s, now) {
    if (now - this.statusAt >= STATUS_EVERY_MS) {
      setText(this.status, s.status);
      const states = [];
      if (s.force !== null && s.force !== undefined) states.push(`force ${s.force.toFixed(2)} N`);
      states.push(s.contact ? "in contact" : "free");
      if (s.clutched) states.push("clutch held");
      if (s.drifting) states.push("cube drifting");
      setText(this.states, states.join(" · "));
      this.statusAt = now;
    }
    setText(this.touched, s.touched ? `touching ${s.touched}` : "not touching");
    if (this.touched.classList.contains("contact") !== s.contact)
      this.touched.classList.toggle("contact", s.contact);
    const seen = new Set();
    for (const m of s.marks) {
      let badge = this.badges.get(m.id);
      if (!badge) {
        badge = element(this.marks, "div", "mark");
        badge.textContent = String(m.id);
        this.badges.set(m.id, badge);
      }
      if (badge.title !== m.label) badge.title = m.label;
      if (s.markColor && !badge.style.background)
        badge.style.background = `rgb(${s.markColor.map((c) => Math.round(c * 255)).join(",")})`;
      const place = `translate(${m.x.toFixed(0)}px, ${m.y.toFixed(0)}px)`;
      if (badge.style.transform !== place) badge.style.transform = place;
      seen.add(m.id);
    }
    for (const [id, badge] of this.badges)
      if (!seen.has(id)) {
        badge.remove();
        this.badges.delete(id);
      }
  }
}
