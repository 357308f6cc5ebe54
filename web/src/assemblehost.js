// The Assemble panel's place on the page without its code: the panel opens with its button, and
// its modules (the editor, the map's layer, the panel: src/assemblepanel.js) are loaded when it
// is first opened, or when an assembly is seen (anyone's: it opens then, to show it). Until
// then the page carries only the Session's part (src/assembly.js) and the words of the Events
// log (src/assemblyreport.js).

export class AssembleHost {
  /**
   * @param {(id: string) => HTMLElement} $
   * @param {object} deps what AssemblePanel takes (src/assemblepanel.js)
   * @param {(e: Error) => void} [onError] its module could not be loaded (the server away)
   */
  constructor($, deps, onError = () => {}) {
    this.$ = $;
    this.deps = deps;
    this.onError = onError;
    this.panel = null;
    this.loading = null;
    $('asm-open').addEventListener('click', () => this.setOpen($('asm-body').hidden));
  }

  /** Opens or closes the panel; resolves with the panel once its code is loaded (opening). */
  setOpen(on) {
    const b = this.$('asm-open');
    b.setAttribute('aria-expanded', String(on));
    b.textContent = on ? 'Close' : 'Open';
    this.$('asm-body').hidden = !on;
    // Closed, the map is the map again: no sites placed by a click nobody sees.
    if (!on && this.panel?.map.editor) this.panel.setPlacing(false);
    return on ? this.load() : Promise.resolve(this.panel);
  }

  load() {
    this.loading ??= import('./assemblepanel.js').then(({ AssemblePanel }) => {
      const [$, doc, deps] = this.deps;
      this.panel = new AssemblePanel($, doc, deps);
      this.panel.applyScene();
      this.panel.assemblyChanged();
      return this.panel;
    }).catch((e) => {
      this.loading = null; // (tried again on the next open)
      this.setOpen(false);
      this.onError(e);
    });
    return this.loading;
  }

  render() {
    this.panel?.render();
  }

  applyScene() {
    this.panel?.applyScene();
  }

  /** An assembly event, or a `state` that changed it: shown, the panel opened (and loaded) first. */
  assemblyChanged(ev) {
    if (this.panel) this.panel.assemblyChanged(ev);
    else if (this.deps[2].session.state.assembly) this.setOpen(true);
  }
}
