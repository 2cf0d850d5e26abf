from django.urls import path

from training import views

app_name = "training"
urlpatterns = [
    path("models/", views.model_list, name="model-list"),
    path("garage/", views.garage, name="garage"),
    path("tracks/<slug:name>.png", views.track_preview, name="track-preview"),
]
