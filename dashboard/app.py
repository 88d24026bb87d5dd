"""The dashboard application: ``create_app(settings)`` builds it, `vascsim serve` runs it."""

from __future__ import annotations

import secrets
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates

from dashboard import api, pages, rating_pages
from dashboard.analysis import AnalysisCache
from dashboard.auth import LoginRateLimiter
from dashboard.error_pages import install_error_handlers
from dashboard.limits import BodyLimit
from dashboard.settings import DashboardSettings
from dashboard.streams.replay_jobs import ReplayJobs
from dashboard.streams.signals import SignalCache
from metrics.session.registry import display_name
from metrics.units import significant
from recorder.remote.ingest import IngestStore
from recorder.remote.routes import create_app as create_ingest_app
from sessions.catalog import Catalog
from sessions.catalog.store import CatalogStore

HERE = Path(__file__).parent
SECURITY_HEADERS = {
    # every asset is served from here: nothing loads from a CDN, no inline script runs
    "Content-Security-Policy": (
        "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
        "img-src 'self' data: blob:; media-src 'self'; connect-src 'self'; frame-ancestors 'none'; "
        "form-action 'self'; base-uri 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "same-origin",
}


def plotly_bundle() -> Path:
    """plotly.min.js from the installed plotly package (served locally: no internet on hospital networks)."""
    import plotly

    path = Path(plotly.__file__).parent / "package_data" / "plotly.min.js"
    if not path.is_file():
        raise FileNotFoundError(f"plotly.min.js not found at {path}; reinstall with `scripts/bootstrap`")
    return path


def create_app(settings: DashboardSettings, catalog: Catalog | None = None) -> FastAPI:
    """The web application over the catalog at ``settings.database_url`` and the data in ``settings.home``."""
    catalog = catalog or Catalog(settings.database_url)
    ingest_store = _ingest_store(settings, catalog)

    @asynccontextmanager
    async def lifespan(_app: FastAPI):
        yield
        ingest_store.close()

    app = FastAPI(
        lifespan=lifespan,
        title="vascsim dashboard",
        version="1",
        description="Courses, studies and replay review for the vascsim suturing simulator.",
        openapi_url="/api/openapi.json",
        docs_url=None,  # the interactive docs load their assets from a CDN
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.catalog = catalog
    app.state.store = CatalogStore(catalog)  # administration through the domain store
    app.state.ingest = ingest_store
    app.state.analyses = AnalysisCache(app.state.store)
    app.state.signals = SignalCache(settings.home)
    app.state.replays = ReplayJobs(app.state.catalog, settings.home)
    app.state.login_limiter = LoginRateLimiter(settings.login_attempts, settings.login_window_s)
    app.state.templates = Jinja2Templates(directory=str(HERE / "templates"))
    app.state.templates.env.filters["sig"] = significant  # 3 significant figures, no exponent
    app.state.templates.env.filters["metric_name"] = display_name  # "entry angle error", not the key
    app.state.blind_key = secrets.token_bytes(32)  # blinded rating's session names (dashboard.rating_pages)
    install_error_handlers(app)

    @app.middleware("http")
    async def security_headers(request: Request, call_next):
        response = await call_next(request)
        for name, value in SECURITY_HEADERS.items():
            response.headers.setdefault(name, value)
        if request.url.path.startswith("/api") and "cache-control" not in response.headers:
            response.headers["Cache-Control"] = "no-store"
        return response

    app.add_middleware(BodyLimit)  # every route's body limit (dashboard.limits); ingest keeps its own
    app.include_router(api.router)
    app.include_router(pages.router)
    app.include_router(rating_pages.router)
    bundle = plotly_bundle()

    @app.get("/static/vendor/plotly.min.js", include_in_schema=False)
    def plotly_js() -> FileResponse:
        return FileResponse(bundle, media_type="text/javascript", headers={"Cache-Control": "max-age=86400"})

    app.mount("/static", StaticFiles(directory=str(HERE / "static")), name="static")
    app.mount("/ingest", create_ingest_app(ingest_store), name="ingest")
    return app


def _ingest_store(settings: DashboardSettings, catalog: Catalog) -> IngestStore:
    """Remote stations' ingest store (recorder.remote.ingest), authorised by the catalog's station tokens."""
    return IngestStore(settings.ingest_root, CatalogStore(catalog).station_for_token)
