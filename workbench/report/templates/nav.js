(() => {
  const nav = document.getElementById('nav');
  const targets = [...nav.querySelectorAll('a[href^="#"]')]
    .map(a => [a, document.getElementById(a.getAttribute('href').slice(1))]).filter(([a, el]) => el && el.id !== 'top');
  let pending = false;
  const update = () => {
    pending = false;
    // the last part whose top has reached the top of the window (any part in view at the very bottom)
    const bottom = innerHeight + scrollY >= document.documentElement.scrollHeight - 2;
    const line = bottom ? innerHeight - 40 : 100;
    let here = null;
    for (const [a, el] of targets) if (el.getBoundingClientRect().top <= line) here = a;
    if (bottom) {
      // at the bottom the last parts cannot reach the top: the part the reader went to (the address's #id), if shown
      const went = targets.find(([a, el]) => '#' + el.id === decodeURIComponent(location.hash));
      if (went && went[1].getBoundingClientRect().top >= 0 && went[1].getBoundingClientRect().top < innerHeight)
        here = went[0];
    }
    nav.querySelectorAll('a.here').forEach(x => { if (x !== here) x.classList.remove('here'); });
    if (!here || here.classList.contains('here')) return;
    here.classList.add('here');
    if (here.offsetTop < nav.scrollTop || here.offsetTop > nav.scrollTop + nav.clientHeight - 30)
      nav.scrollTop = here.offsetTop - nav.clientHeight / 3;
  };
  const onScroll = () => { if (!pending) { pending = true; requestAnimationFrame(update); } };
  addEventListener('scroll', onScroll, {passive: true});
  addEventListener('hashchange', onScroll);
  update();
})();
