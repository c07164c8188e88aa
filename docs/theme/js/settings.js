// The mkdocs theme's settings, which its base.html writes as an inline script: the site's root (the
// folder above this file's) and the keyboard shortcuts (the theme's defaults: ?, n, p, s).
var base_url = new URL("..", document.currentScript.src).href.replace(/\/$/, ""),
    shortcuts = {"help": 191, "next": 78, "previous": 80, "search": 83};
