"""The instructor station in the browser (issue 46, docs/web.md): the page's messages
(`messages.py`), who may reach it (`access.py`), what it is shown (`view.py`), the live
picture (`picture.py`), the HTTP and WebSocket server (`server.py`) and the static page."""
